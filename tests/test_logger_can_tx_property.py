"""Property: whatever the configuration and whatever the bus says, the logger puts no frame on the
wire outside its allow-list, and none at all when listen-only.

Random `CanSection`s (listen-only or not, OBD-II 11/29-bit, J1939 source address, request PGNs,
RTS answering) meet random traffic on python-can's ``virtual`` bus: arbitrary frames plus the
frames that provoke an answer (OBD-II single and first frames, J1939 RTS to any address, TP.DT).
A third bus object on the channel sees everything on the wire; what the traffic player did not
send was sent by the logger.
"""

from __future__ import annotations

import asyncio
import collections
import itertools

import can
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from haulprofile import contract
from haulprofile.contract import j1939, obd
from haulprofile.logger.clock import Clock
from haulprofile.logger.config import CanSection, J1939Section, ObdSection
from haulprofile.logger.sources.can import CanSource, allowed_tx_ids

_channels = itertools.count()

sections = st.builds(
    CanSection,
    interface=st.just("virtual"),
    listen_only=st.booleans(),
    receive_interval_s=st.sampled_from([0.0, 0.01, 0.02]),
    batch_interval_s=st.just(0.05),
    obd=st.builds(
        ObdSection,
        enabled=st.booleans(),
        rate_hz=st.floats(5.0, 100.0),
        pids=st.lists(st.sampled_from(sorted(obd.PIDS)), min_size=1, max_size=7, unique=True),
        pids_per_request=st.integers(1, 6),
        addressing=st.sampled_from(["11bit", "29bit"]),
        timeout_s=st.floats(0.01, 0.1),
        failed_rounds_before_probe=st.integers(1, 3),
        probe_interval_s=st.floats(0.05, 0.5),
    ),
    j1939=st.builds(
        J1939Section,
        enabled=st.booleans(),
        source_address=st.integers(0, 255),
        request_pgns=st.lists(st.integers(0, 0x3FFFF), max_size=3),
        request_destination=st.integers(0, 255),
        request_interval_s=st.floats(0.02, 0.3),
        answer_rts=st.booleans(),
    ),
)

_bytes8 = st.binary(min_size=0, max_size=8)


@st.composite
def traffic(draw, section: CanSection):
    """Frames for the player: (arbitration id, extended, data)."""
    sa = section.j1939.source_address
    byte = st.integers(0, 255)
    anything = st.one_of(
        st.tuples(st.integers(0, 0x7FF), st.just(False), _bytes8),
        st.tuples(st.integers(0, 0x1FFFFFFF), st.just(True), _bytes8),
    )
    obd_single = st.builds(lambda i, pid, a: (0x7E8 + i, False, bytes([0x03, 0x41, pid, a, 0, 0, 0, 0])),
                           st.integers(0, 7), byte, byte)
    obd_first = st.builds(lambda ext, ecu, n: ((0x18DAF100 | ecu) if ext else 0x7E8 + ecu % 8, ext,
                                               bytes([0x10, n, 0x41, 0x0D, 1, 0x0C, 2, 3])),
                          st.booleans(), byte, st.integers(8, 40))
    obd_next = st.builds(lambda ext, ecu, k: ((0x18DAF100 | ecu) if ext else 0x7E8 + ecu % 8, ext,
                                              bytes([0x20 | k, 1, 2, 3, 4, 5, 6, 7])),
                         st.booleans(), byte, st.integers(1, 15))
    rts = st.builds(lambda sender, dest, packets: (
        j1939.make_id(j1939.PGN_TP_CM, sender, 7, dest), True,
        bytes([j1939.TP_CM_RTS, packets * 7, 0, packets, 0xFF, 0xE3, 0xFE, 0x00])),
        byte, st.one_of(st.just(sa), byte), st.integers(1, 5))
    tp_dt = st.builds(lambda sender, dest, k: (j1939.make_id(j1939.PGN_TP_DT, sender, 7, dest), True,
                                               bytes([k, 1, 2, 3, 4, 5, 6, 7])),
                      byte, st.one_of(st.just(sa), byte), st.integers(1, 5))
    return draw(st.lists(st.one_of(anything, obd_single, obd_first, obd_next, rts, tp_dt), max_size=60))


def _run(section: CanSection, frames: list[tuple[int, bool, bytes]]):
    channel = f"tx-property-{next(_channels)}"
    player = can.Bus(interface="virtual", channel=channel)
    scope = can.Bus(interface="virtual", channel=channel)
    logger_bus = can.Bus(interface="virtual", channel=channel)

    async def main():
        queue = asyncio.Queue(100_000)
        source = CanSource(queue, Clock(), section, logger_bus)
        task = asyncio.create_task(source.run())
        for k, (arb, extended, data) in enumerate(frames):
            player.send(can.Message(arbitration_id=arb, is_extended_id=extended, data=data))
            if k % 10 == 9:
                await asyncio.sleep(0.01)
        await asyncio.sleep(0.15)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        return source, b"".join(queue.get_nowait().payload for _ in range(queue.qsize()))

    source, payload = asyncio.run(main())
    on_wire = collections.Counter()
    while (msg := scope.recv(0)) is not None:
        on_wire[(msg.arbitration_id, msg.is_extended_id, bytes(msg.data))] += 1
    scope.shutdown()
    player.shutdown()
    played = collections.Counter((arb, ext, bytes(data)) for arb, ext, data in frames)
    logged = contract.unpack(contract.CAN_FRAMES, payload) if payload else []
    return source, on_wire - played, logged


@settings(max_examples=20, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_no_frame_outside_the_allow_list(data):
    section = data.draw(sections, label="section")
    frames = data.draw(traffic(section), label="traffic")
    source, sent, logged = _run(section, frames)
    allowed = allowed_tx_ids(section)
    assert {arb for arb, _, _ in sent} <= allowed
    if section.listen_only:
        assert not sent and allowed == frozenset() and source.guard.sent == 0
    tx = collections.Counter(
        (int(r["arbitration_id"]), bool(r["flags"] & contract.CAN_FLAG_EXTENDED), bytes(r["data"][:r["dlc"]]))
        for r in logged if r["flags"] & contract.CAN_FLAG_TX)
    assert tx == sent  # every frame on the wire is in the log, flagged as sent by the logger
