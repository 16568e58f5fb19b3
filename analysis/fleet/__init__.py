"""Fleets: map per log (pipeline to the mass stage, then additive statistics), reduce by summing
per vehicle group, generate a cycle per group, locally or on Dask (``docs/fleet.md``)."""

from .histograms import SparseHistogram
from .output import read_counts
from .road_load import SegmentMoments, fit_truck, segment_moments
from .runner import FleetError, FleetResult, FleetSpec, Group, GroupResult, find_logs, run_fleet
from .statistics import FleetStatistics, LoadBins, log_statistics, sum_statistics
from .tasks import LogResult, LogTask, group_cycle, map_log, reduce_group

__all__ = ["FleetError", "FleetResult", "FleetSpec", "FleetStatistics", "Group", "GroupResult", "LoadBins",
           "LogResult", "LogTask", "SparseHistogram", "find_logs", "group_cycle", "log_statistics", "map_log",
           "SegmentMoments", "fit_truck", "read_counts", "reduce_group", "run_fleet", "segment_moments",
           "sum_statistics"]
