"""Device emulators speaking the real protocols, fed by plain time series.

Used by the tests, the crash drills and ``analyze demo``: an ECU on a python-can bus
(`ecu.EcuEmulator`), register-level I2C sensors behind an SMBus-shaped object (`sensors`), a GPS
writing NMEA into a pseudo-terminal (`gps.GpsEmulator`). `rig.record_drive` runs the real daemon
against all of them.
"""


def record_streams(*args, **kwargs):
    """See `logger.emulators.rig.record_streams`: sensor streams -> MCAP log via the real daemon."""
    from .rig import record_streams as _record_streams
    return _record_streams(*args, **kwargs)


def record_drive(*args, **kwargs):
    """See `logger.emulators.rig.record_drive` (imported lazily: it pulls in the daemon)."""
    from .rig import record_drive as _record_drive
    return _record_drive(*args, **kwargs)
