"""Test data with a known truth, for the test suite and the benchmarks; not used by the analysis.

* `haulprofile.testing.logs`: contract-correct synthetic MCAP logs (J1939 frames at bus rates,
  IMU, barometer, GPS, time sync) whose 100 ms truth is returned beside them: ``write_log``.
* `haulprofile.testing.drives`: synthetic drives with the structure of real truck data (trips
  between stops, gradient from the position on a loop road, payload changing at stops) as
  signals tables: ``synthetic_drive``.

The physics-true vehicle model is `haulprofile.analysis.virtual_truck` (it feeds ``analyze demo``).
"""
