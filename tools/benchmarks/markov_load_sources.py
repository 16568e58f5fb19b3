"""Where a cycle's wheel loads can part from the measured drive's, one source at a time.

``python tools/benchmarks/markov_load_sources.py SIGNALS.parquet [VEHICLE [N_WALKS]]`` prints, for
the load target (`load_criteria.measured_loads`), the drive as the chain counts it (`resample_1hz`)
with its own values and with speed, gradient or all three put at class centres (what a walk that
replays the drive carries), and ``N_WALKS`` (100) pooled walks of 1800 s (`generate`, seed 0):
seconds, standing share, wheel energy per km, the wheel power exceeded 95 / 50 / 5 % of the time and
the damage-equivalent torque ranges k = 3 and 8. Not a benchmark of time (docs/cycles.md, "Stops in
the load target").
"""

from __future__ import annotations

import sys

import pandas as pd

from haulprofile.analysis import kinematics
from haulprofile.analysis.loads import loads_of
from haulprofile.analysis.markov import build_chain, count_transitions
from haulprofile.analysis.markov import classes as cls
from haulprofile.analysis.markov.counting import resample_1hz
from haulprofile.analysis.markov.generate import generate
from haulprofile.analysis.markov.load_criteria import cycle_loads, measured_loads, values_of
from haulprofile.analysis.vehicle import load_vehicle

STANDING_MPS = 0.1
CYCLE_S = 1800.0


def row(name: str, loads: pd.DataFrame) -> str:
    values, _, _ = values_of(loads)
    durations = loads["duration_s"].to_numpy(float)
    standing = durations[loads["speed_mps"].to_numpy(float) < STANDING_MPS].sum() / durations.sum()
    braking, median, peak = values[-4] / 1e3, values[-3] / 1e3, values[-2] / 1e3
    return (f"{name:52s} {durations.sum():8.0f} s  standing {standing:6.1%}  E+ {values[0]:.3f}  E- {values[1]:.3f} "
            f"kWh/km  P {braking:7.1f} / {median:5.1f} / {peak:6.1f} kW  DET {values[2]:5.0f} / {values[7]:5.0f} Nm")


def main(argv: list[str]) -> None:
    signals = pd.read_parquet(argv[0])
    vehicle = load_vehicle(argv[1] if len(argv) > 1 else "rigid-18t")
    n_walks = int(argv[2]) if len(argv) > 2 else 100
    widths = cls.ClassWidths()
    print(row("load target (measured_loads)", measured_loads(signals, vehicle)))
    counted = resample_1hz(signals)
    time = counted["time_s"].to_numpy(float)
    speed = counted["speed_mps"].to_numpy(float)
    own = counted.assign(accel_mps2=kinematics.acceleration_mps2(time, speed))
    centre_speed = cls.class_index(speed, widths.speed_mps) * widths.speed_mps
    at_centres = {"speed_mps": centre_speed, "accel_mps2": kinematics.acceleration_mps2(time, centre_speed)}
    gradient = cls.class_index(counted["gradient_pct"], widths.gradient_pct) * widths.gradient_pct
    mass = cls.class_index(counted["mass_kg"], widths.mass_kg) * widths.mass_kg
    print(row("counted 1 Hz, own values", loads_of(own, vehicle)))
    print(row("counted 1 Hz, speed at class centres", loads_of(own.assign(**at_centres), vehicle)))
    print(row("counted 1 Hz, gradient at class centres", loads_of(own.assign(gradient_pct=gradient), vehicle)))
    print(row("counted 1 Hz, speed, gradient, mass at class centres",
              loads_of(own.assign(**at_centres, gradient_pct=gradient, mass_kg=mass), vehicle)))
    chain = build_chain(count_transitions(counted, widths))
    walks = generate(chain, CYCLE_S, n_walks, seed=0)
    pooled = pd.concat([cycle_loads(walks.frame(i), vehicle) for i in range(n_walks)], ignore_index=True)
    print(row(f"{n_walks} walks of {CYCLE_S:.0f} s, pooled", pooled))


if __name__ == "__main__":
    main(sys.argv[1:])
