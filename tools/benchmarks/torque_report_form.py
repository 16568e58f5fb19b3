"""The masses of one drive whose engine reports its torque net and as the indicated torque.

``python tools/benchmarks/torque_report_form.py [SEED]`` drives urban-delivery and long-haul at
``typical`` and ``harsh`` twice, the virtual truck's torque report net of the friction and in
J1939-71's indicated form (`Realism.torque_report`), analyses each up to the gradient and prints
every scored segment's joint mass error [%] (exact vehicle, smoother gradient): net, indicated, and
indicated with SPN 514 taken out of the table (which is what the analysis did before it took the
friction off an indicated report). Not a benchmark of time (docs/estimation.md, "The torque report
in J1939-71's own form").
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from haulprofile.analysis.engine_torque import FRICTION_COLUMN
from haulprofile.analysis.virtual_truck import drive, realism_level
from haulprofile.testing.accuracy import Case, analysed_to_gradient, case_scenario, mass_errors

DRIVES = (("urban-delivery", 8000.0, 0.0), ("long-haul", 15000.0, 600.0))


def signals_of(virtual):
    """The signals table of a virtual drive, up to the gradient."""
    with tempfile.TemporaryDirectory(prefix="haulprofile-torque-form-") as tmp:
        return analysed_to_gradient(virtual, Path(tmp)).signals


def main(argv: list[str]) -> None:
    seed = int(argv[0]) if argv else 1
    for shape, length_m, stop_s in DRIVES:
        for level in ("typical", "harsh"):
            rows = {}
            for form in ("net", "indicated"):
                virtual = drive(case_scenario(Case(shape, level, seed, length_m, stop_s)), seed=seed,
                                realism=realism_level(level, torque_report=form))
                signals = signals_of(virtual)
                rows[form] = mass_errors(signals, virtual.truth, virtual.vehicle, "gradient_smooth_pct")["mass_kg"]
                if form == "indicated":
                    rows["indicated, SPN 514 left out"] = mass_errors(
                        signals.drop(columns=FRICTION_COLUMN), virtual.truth, virtual.vehicle,
                        "gradient_smooth_pct")["mass_kg"]
            for name, errors in rows.items():
                print(f"{shape} {level} seed {seed}, {name}: " + " ".join(f"{100 * e:+.1f}" for e in errors))


if __name__ == "__main__":
    main(sys.argv[1:])
