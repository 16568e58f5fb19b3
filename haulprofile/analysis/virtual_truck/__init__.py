"""The virtual truck: a deterministic, seeded, physics-true scenario generator (``docs/virtual-truck.md``).

    scenario = load_scenario("regional-tunnel")
    drive_ = drive(scenario, load_vehicle("rigid-18t"), seed=0)
    drive_.truth                  # 10 Hz ground truth
    drive_.sensors["engine"]      # EEC1 at 100 Hz, J1939 resolution
    write_dem(drive_, "dem/")     # SRTM .hgt tiles of the terrain
    write_mcap(drive_, "logs/virtual.mcap")
"""

from .dem import write_dem
from .mcap_log import write_mcap
from .scenario import SCENARIOS, Scenario, ScenarioFileError, load_scenario
from .truck import TRUTH_COLUMNS, VirtualDrive, drive, scenario_vehicle

__all__ = ["SCENARIOS", "Scenario", "ScenarioFileError", "TRUTH_COLUMNS", "VirtualDrive", "drive",
           "load_scenario", "scenario_vehicle", "write_dem", "write_mcap"]
