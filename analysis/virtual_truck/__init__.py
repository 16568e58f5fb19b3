"""The virtual truck: a deterministic, seeded, physics-true scenario generator (``docs/virtual-truck.md``).

    scenario = load_scenario("regional-tunnel")
    drive_ = drive(scenario, load_vehicle("rigid-18t"), seed=0, realism="typical")
    drive_.truth                  # 10 Hz ground truth
    drive_.sensors["engine"]      # EEC1 at 100 Hz, J1939 resolution
    write_dem(drive_, "dem/")     # SRTM .hgt tiles of the terrain (with the level's DEM errors)
    write_mcap(drive_, "logs/virtual.mcap")
    write_truth(drive_, "truth/") # road per 10 m, mass per segment, injected errors
"""

from .dem import write_dem
from .mcap_log import write_mcap
from .realism import LEVELS, Realism, realism_level
from .scenario import SCENARIOS, Scenario, ScenarioFileError, load_scenario
from .truck import TRUTH_COLUMNS, VirtualDrive, drive, scenario_vehicle
from .truth import write_truth

__all__ = ["LEVELS", "SCENARIOS", "Realism", "Scenario", "ScenarioFileError", "TRUTH_COLUMNS", "VirtualDrive", "drive",
           "load_scenario", "realism_level", "scenario_vehicle", "write_dem", "write_mcap", "write_truth"]
