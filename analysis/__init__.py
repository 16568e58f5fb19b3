"""haulprofile analysis: logs to gradient, mass, representative cycles, wheel loads and simulation.

The stages are importable from here (imported on first use, so ``import analysis`` stays light)::

    from haulprofile import analysis
    result = analysis.run("logs/", vehicle="rigid-18t", dem="dem/")
    result.signals.plot(x="time_s", y=["speed_mps", "gradient_pct"])
"""

from importlib import import_module

_EXPORTS = {
    "run": "haulprofile.analysis.api", "RunResult": "haulprofile.analysis.api",
    "load_vehicle": "haulprofile.analysis.vehicle", "Vehicle": "haulprofile.analysis.vehicle",
    "read_signals": "haulprofile.analysis.signals", "write_signals": "haulprofile.analysis.signals",
    "read_vdri": "haulprofile.analysis.vecto", "write_vdri": "haulprofile.analysis.vecto",
    "read_logs": "haulprofile.analysis.ingest", "ingest_logs": "haulprofile.analysis.ingest",
    "estimate_gradient": "haulprofile.analysis.gradient", "estimate_mass": "haulprofile.analysis.mass",
    "open_dem": "haulprofile.analysis.dem",
    "count_transitions": "haulprofile.analysis.markov", "select_cycle": "haulprofile.analysis.markov", "ClassWidths": "haulprofile.analysis.markov",
    "collectives_of": "haulprofile.analysis.loads",
    "simulate_cycle": "haulprofile.analysis.simulate", "read_cycle": "haulprofile.analysis.simulate",
    "RunContext": "haulprofile.analysis.pipeline", "Options": "haulprofile.analysis.pipeline",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'haulprofile.analysis' has no attribute {name!r}")
