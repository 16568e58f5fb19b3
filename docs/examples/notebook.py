"""From a truck's logs to its load profile in a few lines of Python (what a notebook does).

Run it as ``python docs/examples/notebook.py [OUT_DIR]``: it makes a short virtual-truck drive so it
needs no data; replace the first block by your own logs, DEM and vehicle file.
"""

import sys
from pathlib import Path

from haulprofile import analysis
from haulprofile.analysis.virtual_truck import drive, load_scenario, write_dem, write_mcap

out = Path(sys.argv[1] if len(sys.argv) > 1 else "notebook-out")
truck = drive(load_scenario("regional-tunnel"), analysis.load_vehicle("rigid-18t"), seed=1)
write_mcap(truck, out / "logs" / "drive.mcap")
write_dem(truck, out / "dem")

# The five lines:
result = analysis.run(out / "logs", vehicle="rigid-18t", dem=out / "dem", out=out / "run",
                      cycle={"n_candidates": 2000})
print(result.mass_segments[["start_s", "end_s", "mass_ls_kg", "uncertainty_kg", "status"]])
print(result.signals[["time_s", "speed_mps", "gradient_pct", "mass_kg"]].describe())
truck_e = analysis.load_vehicle("rigid-18t")
energy = analysis.simulate_cycle(analysis.read_cycle(out / "run" / "cycle.vdri", truck_e), truck_e)
print(f"cycle score {result.summary['cycle']['score']:.3f}; "
      f"{energy.summary['battery_kwh_per_km']:.3f} kWh/km at the battery; report: {out / 'run' / 'report.html'}")
