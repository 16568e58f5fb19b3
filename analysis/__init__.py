"""haulprofile analysis: logs to gradient, mass, representative cycles, wheel loads and simulation.

The stages are importable from here (imported on first use, so ``import analysis`` stays light)::

    import analysis
    result = analysis.run("logs/", vehicle="rigid-18t", dem="dem/")
    result.signals.plot(x="time_s", y=["speed_mps", "gradient_pct"])
"""

from importlib import import_module

_EXPORTS = {
    "run": "analysis.api", "RunResult": "analysis.api",
    "load_vehicle": "analysis.vehicle", "Vehicle": "analysis.vehicle",
    "read_signals": "analysis.signals", "write_signals": "analysis.signals",
    "read_vdri": "analysis.vecto", "write_vdri": "analysis.vecto",
    "read_logs": "analysis.ingest", "ingest_logs": "analysis.ingest",
    "estimate_gradient": "analysis.gradient", "estimate_mass": "analysis.mass",
    "open_dem": "analysis.dem",
    "count_transitions": "analysis.markov", "select_cycle": "analysis.markov", "ClassWidths": "analysis.markov",
    "collectives_of": "analysis.loads",
    "simulate_cycle": "analysis.simulate", "read_cycle": "analysis.simulate",
}
_RENAMED = {"simulate_cycle": "simulate"}
"""``analysis.simulate`` is the subpackage, so its function is exported as ``simulate_cycle``."""

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(_EXPORTS[name]), _RENAMED.get(name, name))
    raise AttributeError(f"module 'analysis' has no attribute {name!r}")
