"""CAN source against the ECU emulator on python-can's ``virtual`` bus: OBD-II (11/29-bit,
ISO-TP multi-frame, timeouts and back-off), J1939 requests, BAM and RTS/CTS, the transmit
allow-list and listen-only, and a real CANedge recording replayed onto the bus.

A second bus object on the same virtual channel is the "oscilloscope": it sees every frame the
logger puts on the wire. (socketcan/vcan is not available here; the socketcan path differs only
in the bus object python-can returns.)
"""

from __future__ import annotations

import asyncio
import time

import can
import numpy as np
import pytest

from haulprofile import contract
from haulprofile.contract import j1939, obd
from haulprofile.logger.clock import Clock
from haulprofile.logger.config import CanSection
from haulprofile.logger.emulators.ecu import EcuEmulator
from haulprofile.logger.emulators.signals import TimeSeries
from haulprofile.logger.sources.can import CanSource, allowed_tx_ids
from haulprofile.logger.sources.can_protocols import ObdPoller

SIGNALS = {
    "time_s": np.array([0.0, 100.0]),
    "wheel_speed_kmh": np.array([63.4, 63.4]),
    "engine_speed_rpm": np.array([1337.25, 1337.25]),
    "actual_engine_torque_pct": np.array([41.0, 41.0]),
    "driver_demand_torque_pct": np.array([44.0, 44.0]),
    "engine_reference_torque_nm": np.array([2300.0, 2300.0]),
    "pressure_pa": np.array([94_800.0, 94_800.0]),
    "temperature_c": np.array([17.0, 17.0]),
}

_channel_counter = iter(range(10_000))


def run_can(section: CanSection, seconds: float, answer_obd: bool = True, broadcast: bool = True,
            setup=None):
    """Run a CanSource with an ECU emulator for ``seconds``; returns (frames, source, ecu, scope frames)."""
    channel = f"test-can-{next(_channel_counter)}"
    clock = Clock()
    ecu_bus = can.Bus(interface="virtual", channel=channel)
    scope = can.Bus(interface="virtual", channel=channel)
    logger_bus = can.Bus(interface="virtual", channel=channel)
    ecu = EcuEmulator(ecu_bus, TimeSeries(SIGNALS), clock, answer_obd=answer_obd, broadcast=broadcast)
    messages = []

    async def main():
        queue = asyncio.Queue(10_000)
        source = CanSource(queue, clock, section, logger_bus, say=messages.append)
        if setup:
            setup(source)
        ecu.start()
        task = asyncio.create_task(source.run())
        await asyncio.sleep(seconds)
        source.obd_at_end = source.obd.stats() if source.obd else None
        await asyncio.get_running_loop().run_in_executor(None, ecu.stop)
        await asyncio.sleep(0.05)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        payloads = []
        while not queue.empty():
            payloads.append(queue.get_nowait().payload)
        return source, payloads

    source, payloads = asyncio.run(main())
    frames = contract.unpack(contract.CAN_FRAMES, b"".join(payloads)) if payloads else \
        np.zeros(0, contract.CAN_FRAME_DTYPE)
    seen = []
    while (msg := scope.recv(0)) is not None:
        seen.append(msg)
    scope.shutdown()
    ecu_bus.shutdown()
    source.messages = messages
    return frames, source, ecu, seen


def _logger_frames(seen, ecu):
    ecu_frames = {(a, bytes(d)) for a, _, d in ecu.sent}
    return [m for m in seen if (m.arbitration_id, bytes(m.data)) not in ecu_frames]


@pytest.mark.parametrize("receive_interval_s", [0.02, 0.0])
def test_obd_11bit_polling_at_the_configured_rate(receive_interval_s):
    """On the reader's 20 ms cadence and with a wake-up per frame (``receive_interval_s = 0``)."""
    section = CanSection(interface="virtual", listen_only=False, receive_interval_s=receive_interval_s)
    section.j1939.request_pgns = []
    frames, source, ecu, seen = run_can(section, 1.0)
    stats = source.obd_at_end
    requests_ns = frames["t_mono_ns"][(frames["flags"] & contract.CAN_FLAG_TX) != 0].astype(np.int64)
    # how many fit depends on the scheduler, not the poller (its rate is held on a fake clock below);
    # what the log must show is polling that never outruns the configured rate
    period_ns = 1e9 / section.obd.rate_hz
    assert stats["obd_requests"] >= 3
    assert len(requests_ns) <= (requests_ns[-1] - requests_ns[0]) / period_ns + 2
    assert stats["obd_timeouts"] == 0
    assert stats["obd_responses"] >= stats["obd_requests"] - 1  # the last one may be in flight at the stop
    responses = frames[frames["arbitration_id"] == 0x7E8]
    by_pid = {int(r["data"][2]): bytes(r["data"]) for r in responses}
    # SAE J1979 formulas written out: speed A km/h, rpm (256A+B)/4, torque A-125 %, ref torque 256A+B Nm
    assert by_pid[0x0D][3] == 63
    assert (256 * by_pid[0x0C][3] + by_pid[0x0C][4]) / 4 == 1337.25
    assert by_pid[0x62][3] - 125 == 41
    assert 256 * by_pid[0x63][3] + by_pid[0x63][4] == 2300
    assert by_pid[0x33][3] == 95 and by_pid[0x46][3] - 40 == 17
    requests = frames[(frames["flags"] & contract.CAN_FLAG_TX) != 0]
    assert set(requests["arbitration_id"].tolist()) == {obd.FUNCTIONAL_REQUEST_ID_11BIT}


def test_obd_29bit_addressing():
    section = CanSection(interface="virtual", listen_only=False)
    section.obd.addressing = "29bit"
    section.j1939.request_pgns = []
    frames, source, ecu, seen = run_can(section, 0.5)
    assert source.obd.responses >= 10
    tx = {m.arbitration_id for m in _logger_frames(seen, ecu)}
    assert tx == {obd.FUNCTIONAL_REQUEST_ID_29BIT}
    assert np.any(frames["arbitration_id"] == obd.RESPONSE_ID_29BIT_BASE)


def test_isotp_multi_frame_response_gets_flow_control_and_is_reassembled():
    section = CanSection(interface="virtual", listen_only=False)
    section.obd.pids = [0x0D, 0x0C, 0x62, 0x63, 0x61, 0x33]
    section.obd.pids_per_request = 6
    section.j1939.request_pgns = []
    payloads = []

    def capture(source):
        original = source.obd.on_response
        source.obd.on_response = lambda arb, payload: (payloads.append(payload), original(arb, payload))

    frames, source, ecu, seen = run_can(section, 0.5, broadcast=False, setup=capture)
    assert source.obd.responses >= 5
    flow_controls = [m for m in _logger_frames(seen, ecu) if m.arbitration_id == 0x7E0]
    assert flow_controls and all(m.data[0] == 0x30 for m in flow_controls)
    payload = payloads[0]
    assert len(payload) == 1 + 6 + 1 + 2 + 1 + 2 + 1 + 1
    assert payload[:2] == bytes([0x41, 0x0D]) and payload[2] == 63
    assert payload[3] == 0x0C and (256 * payload[4] + payload[5]) / 4 == 1337.25
    first = frames[(frames["arbitration_id"] == 0x7E8) & ((frames["data"][:, 0] >> 4) == 1)]
    assert len(first) == len(flow_controls)


def test_no_ecu_answers_backs_off_to_a_slow_probe():
    section = CanSection(interface="virtual", listen_only=False)
    section.obd.timeout_s = 0.02
    section.obd.failed_rounds_before_probe = 1
    section.obd.probe_interval_s = 0.5
    section.j1939.request_pgns = []
    frames, source, ecu, seen = run_can(section, 1.5, answer_obd=False)
    stats = source.obd_at_end
    assert stats["obd_state"].startswith("probing")
    assert stats["obd_responses"] == 0
    assert len(section.obd.pids) <= stats["obd_requests"] <= len(section.obd.pids) + 4
    assert stats["obd_timeouts"] == stats["obd_requests"]
    assert any("probing every 0.5 s" in m for m in source.messages)



def _poll_on_fake_clock(poller: ObdPoller, end_ns: int, answer_after_ns: int, stall: tuple[int, int] | None = None):
    """Drive ``poller`` as the reader thread does, on a fake clock: tick at each time it asks for,
    every request answered ``answer_after_ns`` later; in ``stall`` = (from, to) the thread does
    not run. Returns the send times [ns]."""
    sent_ns, answer = [], None
    now_ns = 0
    while now_ns < end_ns:
        if stall and stall[0] <= now_ns < stall[1]:
            now_ns = stall[1]
        if answer is not None and now_ns >= answer[0]:
            poller.on_response(0x7E8, bytes([0x41, answer[1]]))
            answer = None
        before = poller.requests
        due_ns = poller.tick(now_ns)
        if poller.requests > before:
            sent_ns.append(now_ns)
            answer = (now_ns + answer_after_ns, poller.groups[(poller.requests - 1) % len(poller.groups)][0])
        now_ns = max(due_ns if answer is None else min(due_ns, answer[0]), now_ns + 1)
    return np.array(sent_ns)


def test_obd_poller_holds_its_rate_and_catches_up_one_request_after_a_stall():
    """On a fake clock (the real-bus test above cannot say how many requests a loaded machine lets
    through): 30 Hz gives 30 requests in a second, one per slot; a reader thread that stalls for
    150 ms sends one request late and one at once after it, never a burst of the missed slots; the
    slots go on a period apart from the stall's end."""
    section = CanSection(interface="virtual", listen_only=False).obd
    period_ns = int(1e9 / section.rate_hz)
    sent = _poll_on_fake_clock(ObdPoller(_PollerSource(), section), 30 * period_ns, 2_000_000)
    assert len(sent) == 30
    assert np.all(np.abs(sent - period_ns * np.arange(30)) < period_ns / 100)
    stalled = _poll_on_fake_clock(ObdPoller(_PollerSource(), section), 30 * period_ns, 2_000_000,
                                  stall=(500_000_000, 650_000_000))
    after = stalled[stalled >= 650_000_000]
    assert np.sum(after < 650_000_000 + period_ns) == 2
    assert np.all(np.diff(np.r_[after[0], after[2:]]) >= period_ns - 1)
    assert len(stalled) < len(sent)


class _PollerSource:
    """What `ObdPoller` sees of the CAN source: a guard that sends every request, a ``say`` kept."""

    def __init__(self):
        self.messages: list[str] = []
        self.guard = type("Guard", (), {"send": staticmethod(lambda *request: True)})()

    def say(self, message: str) -> None:
        self.messages.append(message)


def _flap(poller: ObdPoller, spells: int) -> None:
    """``spells`` times: a whole round unanswered (the poller gives up), then its probe answered."""
    now_ns = 0
    for _ in range(spells):
        while not poller.probing:
            now_ns = max(poller.tick(now_ns), now_ns + 1)
        sent = poller.requests
        while poller.requests == sent:
            now_ns = max(poller.tick(now_ns), now_ns + 1)
        poller.on_response(0x7E8, bytes([0x41, poller.groups[0][0]]))
        poller.tick(now_ns + 1)
        assert not poller.probing


def test_obd_answers_that_come_and_go_are_said_once_and_counted():
    section = CanSection(interface="virtual", listen_only=False).obd
    section.failed_rounds_before_probe = 1
    source = _PollerSource()
    poller = ObdPoller(source, section)
    _flap(poller, 30)
    gave_up = [m for m in source.messages if "no ECU answered" in m]
    back = [m for m in source.messages if "answers OBD-II again" in m]
    assert len(gave_up) == 1 and len(back) == 1
    assert poller.give_ups == 30 and poller.stats()["obd_give_ups"] == 30
    _flap(poller, 70)  # the 100th spell is said again, with its count
    gave_up = [m for m in source.messages if "no ECU answered" in m]
    assert len(gave_up) == 2 and "100th time" in gave_up[1]
    assert len([m for m in source.messages if "answers OBD-II again" in m]) == 2

def test_listen_only_transmits_nothing():
    section = CanSection(interface="virtual", listen_only=True)
    frames, source, ecu, seen = run_can(section, 0.5)
    assert _logger_frames(seen, ecu) == []
    assert source.guard.sent == 0 and allowed_tx_ids(section) == frozenset()
    assert len(frames) == len(ecu.sent) > 20


def test_only_allow_listed_ids_go_on_the_wire():
    section = CanSection(interface="virtual", listen_only=False)
    section.j1939.request_interval_s = 0.2
    frames, source, ecu, seen = run_can(section, 0.6)
    sent = _logger_frames(seen, ecu)
    assert sent and {m.arbitration_id for m in sent} <= allowed_tx_ids(section)
    assert source.guard.send(0x123, b"\x00" * 8, False) is False
    assert source.guard.blocked == 1
    allowed = allowed_tx_ids(section)
    assert obd.FUNCTIONAL_REQUEST_ID_11BIT in allowed and 0x7E0 in allowed
    assert j1939.make_id(j1939.PGN_REQUEST, 0xF9, 6, 0xFF) in allowed
    assert not any(a in allowed for a in (0x000, 0x7E8, j1939.make_id(j1939.PGN_EEC1, 0xF9)))


def _reassemble(frames, sender: int) -> bytes:
    dt_id = lambda a: (a >> 8) & 0xFF00 == j1939.PGN_TP_DT and (a & 0xFF) == sender  # noqa: E731
    packets = [bytes(f["data"]) for f in frames if f["flags"] & contract.CAN_FLAG_EXTENDED and dt_id(int(f["arbitration_id"]))]
    return b"".join(p[1:] for p in packets)


def test_j1939_global_request_is_answered_by_bam():
    section = CanSection(interface="virtual", listen_only=False)
    section.obd.enabled = False
    section.j1939.request_pgns = [j1939.PGN_EC1, j1939.PGN_CVW]
    frames, source, ecu, seen = run_can(section, 0.6, broadcast=False)
    ids = frames["arbitration_id"].astype(np.int64)
    bam = frames[(ids >> 8 & 0x3FF00) == j1939.PGN_TP_CM]
    assert len(bam) == 1 and bam["data"][0][0] == j1939.TP_CM_BAM
    data = _reassemble(frames, 0x00)[:39]
    assert j1939.decode_pgn(j1939.PGN_EC1, data)["engine_reference_torque_nm"] == 2300.0
    assert np.any((ids >> 8 & 0x3FFFF) == j1939.PGN_CVW)


def test_j1939_rts_addressed_to_the_logger_is_answered_with_cts_and_ack():
    section = CanSection(interface="virtual", listen_only=False)
    section.obd.enabled = False
    section.j1939.request_pgns = [j1939.PGN_EC1]
    section.j1939.request_destination = 0x00
    frames, source, ecu, seen = run_can(section, 0.5, broadcast=False)
    cm = frames[((frames["arbitration_id"].astype(np.int64) >> 8) & 0x3FF00) == j1939.PGN_TP_CM]
    kinds = [int(d[0]) for d in cm["data"]]
    assert kinds == [j1939.TP_CM_RTS, j1939.TP_CM_CTS, j1939.TP_CM_EOM_ACK]
    assert [bool(f & contract.CAN_FLAG_TX) for f in cm["flags"]] == [False, True, True]
    assert int(cm["arbitration_id"][1]) == j1939.make_id(j1939.PGN_TP_CM, 0xF9, 7, 0x00)
    data = _reassemble(frames, 0x00)[:39]
    assert j1939.decode_pgn(j1939.PGN_EC1, data)["engine_reference_torque_nm"] == 2300.0


def test_real_canedge_recording_replayed_is_logged_frame_for_frame(data_dir):
    asammdf = pytest.importorskip("asammdf")
    mdf = asammdf.MDF(str(data_dir / "real-can" / "css-j1939-tp-186s.MF4"))
    recorded = []
    for index, group in enumerate(mdf.groups):
        if "CAN_DataFrame.ID" not in {c.name for c in group.channels}:
            continue
        ids = mdf.get("CAN_DataFrame.ID", group=index, raw=True)
        data = mdf.get("CAN_DataFrame.DataBytes", group=index, raw=True).samples
        dlc = mdf.get("CAN_DataFrame.DLC", group=index, raw=True).samples
        ide = mdf.get("CAN_DataFrame.IDE", group=index, raw=True).samples
        for t, i, d, n, e in zip(ids.timestamps, ids.samples, data, dlc, ide):
            recorded.append((float(t), int(i) & 0x1FFFFFFF, bytes(d[:min(int(n), 8)]), bool(e)))
    mdf.close()
    recorded.sort(key=lambda r: r[0])
    assert len(recorded) == 1815
    section = CanSection(interface="virtual", listen_only=True)
    channel = "test-can-replay"
    player = can.Bus(interface="virtual", channel=channel)
    logger_bus = can.Bus(interface="virtual", channel=channel)

    async def main():
        queue = asyncio.Queue(10_000)
        source = CanSource(queue, Clock(), section, logger_bus)
        task = asyncio.create_task(source.run())
        await asyncio.sleep(0.05)
        for k, (_, arb, data, ext) in enumerate(recorded):
            player.send(can.Message(arbitration_id=arb, data=data, is_extended_id=ext))
            if k % 200 == 199:
                await asyncio.sleep(0.02)
        await asyncio.sleep(0.3)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        return [queue.get_nowait().payload for _ in range(queue.qsize())]

    frames = contract.unpack(contract.CAN_FRAMES, b"".join(asyncio.run(main())))
    player.shutdown()
    assert len(frames) == len(recorded)
    assert frames["arbitration_id"].tolist() == [r[1] for r in recorded]
    assert [bytes(f["data"][:f["dlc"]]) for f in frames] == [r[2] for r in recorded]
    assert [bool(f & contract.CAN_FLAG_EXTENDED) for f in frames["flags"]] == [r[3] for r in recorded]
    assert np.all(np.diff(frames["t_mono_ns"].astype(np.int64)) >= 0)
    assert abs(int(frames["t_mono_ns"][-1]) - time.monotonic_ns()) < 10e9


def test_socketcan_vcan_frames_carry_the_kernel_timestamp():
    try:
        ecu_bus = can.Bus(interface="socketcan", channel="vcan0")
        logger_bus = can.Bus(interface="socketcan", channel="vcan0")
    except Exception as exc:  # no vcan module, no interface, not Linux
        pytest.skip(f"needs a vcan0 interface (modprobe vcan; ip link add vcan0 type vcan; "
                    f"ip link set vcan0 up): {exc}")
    section = CanSection(interface="socketcan", channel="vcan0", listen_only=True)
    clock = Clock()
    ecu = EcuEmulator(ecu_bus, TimeSeries(SIGNALS), clock, answer_obd=False)

    async def main():
        queue = asyncio.Queue(1000)
        source = CanSource(queue, clock, section, logger_bus)
        ecu.start()
        task = asyncio.create_task(source.run())
        await asyncio.sleep(0.5)
        await asyncio.get_running_loop().run_in_executor(None, ecu.stop)
        await asyncio.sleep(0.05)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        return [queue.get_nowait().payload for _ in range(queue.qsize())]

    frames = contract.unpack(contract.CAN_FRAMES, b"".join(asyncio.run(main())))
    ecu_bus.shutdown()
    assert len(frames) == len(ecu.sent) > 20
    assert np.all(frames["flags"] & contract.CAN_FLAG_HW_TIMESTAMP)
    assert abs(int(frames["t_mono_ns"][-1]) - time.monotonic_ns()) < 5e9


def test_a_second_bus_is_logged_listen_only_with_its_channel_index():
    """``can.more_channels``: each further bus is a source of its own, its frames carry channel 1."""
    from haulprofile.logger.config import Config
    from haulprofile.logger.emulators.rig import EmulatedDevices, emulation_config
    from haulprofile.logger.sources.can import listening_section

    config = emulation_config("unused", 1.0, Config())
    config.can.more_channels = ["haulprofile-test-bus-1"]
    second = listening_section(config.can, "haulprofile-test-bus-1")
    assert second.listen_only and not allowed_tx_ids(second) and second.more_channels == []
    clock = Clock()
    devices = EmulatedDevices(TimeSeries({"time_s": np.array([0.0, 100.0])}), clock)

    async def run():
        queue = asyncio.Queue()
        devices.start(config)
        sources = [s for s in devices.build_sources(config, queue, clock, lambda m: None) if s.name.startswith("can")]
        other = can.Bus(interface="virtual", channel="haulprofile-test-bus-1", receive_own_messages=False)
        tasks = [asyncio.create_task(s.run()) for s in sources]
        await asyncio.sleep(0.1)
        for k in range(50):
            other.send(can.Message(arbitration_id=j1939.make_id(65262, 0x21), data=bytes([k] * 8), is_extended_id=True))
        await asyncio.sleep(0.5)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for source in sources:
            await source.close()
        other.shutdown()
        devices.close()
        items = []
        while not queue.empty():
            items.append(queue.get_nowait())
        return sources, items

    sources, items = asyncio.run(run())
    assert [s.name for s in sources] == ["can", "can1"]
    frames = np.concatenate([contract.unpack(contract.CAN_FRAMES, i.payload) for i in items if i.topic is contract.CAN_FRAMES])
    ours = frames[frames["channel"] == 1]
    assert len(ours) == 50 and np.array_equal(ours["data"][:, 0], np.arange(50))
    assert not np.any(ours["flags"] & contract.CAN_FLAG_TX)
    assert sources[1].guard.sent == 0
