"""The log directory removed or replaced by a file while the daemon logs: it says so, keeps every
byte already written (the open file is written back from its descriptor) and goes on in a directory
made again, or stops with exit code 1 where a file stands in the directory's place. Counts of
files and records are checked, never how long anything took."""

from __future__ import annotations

import asyncio
import shutil

from test_fault_drills import read_log

from haulprofile.logger.clock import Clock
from haulprofile.logger.config import Config
from haulprofile.logger.daemon import Daemon
from haulprofile.logger.emulators.faults import faulty_devices
from haulprofile.logger.emulators.rig import emulation_config, run_daemon_for
from haulprofile.logger.emulators.signals import TimeSeries, synthetic_drive


def log_while(directory, inject, duration_s=4.0):
    config = emulation_config(directory, 1.0, Config())
    clock = Clock()
    devices = faulty_devices(TimeSeries(synthetic_drive(30.0)), clock).start(config)
    daemon = Daemon(config, devices, clock)
    said = []
    daemon.say = lambda message: said.append(message) or Daemon.say(daemon, message)

    async def main():
        task = asyncio.create_task(run_daemon_for(daemon, devices, duration_s))
        await daemon.ready.wait()
        await asyncio.sleep(1.5)
        await inject(daemon)
        return await task

    return asyncio.run(main()), said


def test_a_removed_log_directory_is_made_again_and_the_open_file_written_back(tmp_path):
    directory = tmp_path / "logs"
    before = {}

    async def remove(daemon):
        before["name"] = daemon.storage.path.name
        shutil.rmtree(directory)

    code, said = log_while(directory, remove)
    assert code == 0
    assert any("was removed" in line and "written back" in line for line in said), said
    files = sorted(directory.glob("*.mcap"))
    assert before["name"] in [p.name for p in files] and len(files) == 2
    log = read_log(files)
    assert all(complete for _, complete in log.files)
    first = read_log([directory / before["name"]])
    assert len(first.can()) > 100, "what was logged before the removal is kept"
    assert len(log.can()) > len(first.can()), "and logging went on"


def test_a_file_in_place_of_the_log_directory_stops_the_daemon_with_the_data_beside_it(tmp_path):
    directory = tmp_path / "logs"
    before = {}

    async def replace(daemon):
        before["name"] = daemon.storage.path.name
        shutil.rmtree(directory)
        directory.write_text("not a directory")

    code, said = log_while(directory, replace)
    assert code == 1
    assert any("replaced by a file" in line and "logging stops" in line for line in said), said
    rescued = tmp_path / f"logs.rescued-{before['name']}"
    log = read_log([rescued])
    assert log.files[0][1] and len(log.can()) > 100
    assert directory.read_text() == "not a directory"
