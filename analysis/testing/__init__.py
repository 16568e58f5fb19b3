"""Test data with a known truth and the harnesses that judge the analysis on it, for the test suite
and the benchmarks; not used by the analysis.

* `haulprofile.testing.logs`: contract-correct synthetic MCAP logs (J1939 frames at bus rates,
  IMU, barometer, GPS, time sync) whose 100 ms truth is returned beside them: ``write_log``.
* `haulprofile.testing.drives`: synthetic drives with the structure of real truck data (trips
  between stops, gradient from the position on a loop road, payload changing at stops) as
  signals tables: ``synthetic_drive``.
* `haulprofile.testing.accuracy`: the accuracy matrix, every stage's estimate on the virtual truck
  against its truth, by realism level and sensor set (``run_case``; ``tools/bench.py accuracy``).
* `haulprofile.testing.fleet`: a virtual fleet of one truck's logs with known masses (``virtual_fleet``).

The physics-true world is `haulprofile.analysis.virtual_truck` (it feeds ``analyze demo``); the
harnesses stand above the pipeline, the world below it.
"""
