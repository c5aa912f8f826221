"""The fast frame packer gives the generated packing's bytes, frame for frame."""

from __future__ import annotations

import random
from typing import Any

import pytest
from test_protocols_fastparse import _random_message

from vtolftc.protocols.fastpack import FramePacker
from vtolftc.protocols.mavlink import SigningConfig, dialect, make_codec


def _wire_values(msg: Any) -> list[Any]:
    """The payload's fields in wire order, arrays flattened (as the generated ``pack``)."""
    out: list[Any] = []
    for name, n in zip(msg.ordered_fieldnames, msg.array_lengths, strict=True):
        v = getattr(msg, name)
        if n and not isinstance(v, bytes | str):
            out.extend(v)
        else:
            out.append(v.encode() if isinstance(v, str) else v)
    return out


@pytest.mark.parametrize("signed", [False, True])
def test_frames_equal_generated_packing_over_the_dialect(signed: bool) -> None:
    mod = dialect()
    rng = random.Random(7)
    sys_id, comp_id = rng.randint(1, 255), rng.randint(0, 255)
    signing = SigningConfig(secret_key=bytes(range(32)), link_id=7, timestamp=2**40 + 5)
    ref_codec = make_codec(sys_id, comp_id, signing=signing if signed else None)
    codec = make_codec(sys_id, comp_id, signing=signing if signed else None)
    checked = 0
    for cls in sorted(set(mod.mavlink_map.values()), key=lambda c: c.id):
        if any(t == "char" for t in cls.fieldtypes):
            continue  # strings are packed by the generated code only (none on the HIL link)
        packer = FramePacker(codec, cls)
        for _ in range(5):
            msg = _random_message(cls, rng)
            seq = rng.randint(0, 255)
            ref_codec.seq = codec.seq = seq
            want = msg.pack(ref_codec)
            got = packer.pack(*_wire_values(msg))
            assert got == want, cls.msgname
            assert codec.seq == (seq + 1) & 0xFF
            assert codec.signing.timestamp == ref_codec.signing.timestamp
        checked += 1
    assert checked > 100


def test_hil_messages_with_zero_tails_and_all_zero_payloads() -> None:
    mod = dialect()
    ref_codec, codec = make_codec(1, 1), make_codec(1, 1)
    cls = mod.MAVLink_hil_actuator_controls_message
    packer = FramePacker(codec, cls)
    for u in ([0.0] * 16, [0.5, -1.0] + [0.0] * 14, [1.0] * 16):
        for mode in (0, 128):
            want = ref_codec.hil_actuator_controls_encode(123456, u, mode, 1).pack(ref_codec)
            ref_codec.seq = (ref_codec.seq + 1) & 0xFF
            assert packer.pack(123456, 1, *u, mode) == want
    assert packer.pack(0, 0, *([0.0] * 16), 0)[1] == 1  # at least one payload byte


def test_signed_frames_verify_on_a_link_with_the_key() -> None:
    """Independent of the generated packing: a receiving codec with the key accepts them."""
    signing = SigningConfig(secret_key=bytes(range(32)))
    codec, rx = make_codec(1, 1, signing=signing), make_codec(2, 2, signing=signing)
    packer = FramePacker(codec, dialect().MAVLink_hil_actuator_controls_message)
    for t in range(1, 4):
        frame = packer.pack(t, 1, *([0.25] * 16), 128)
        msgs = rx.parse_buffer(frame)
        assert msgs is not None and len(msgs) == 1 and msgs[0].get_signed()
        assert msgs[0].time_usec == t and msgs[0].controls[3] == 0.25


@pytest.mark.parametrize("signed", [False, True])
def test_hil_bridge_answer_equals_generated_encoding(signed: bool) -> None:
    """HilBridge.send_controls: the bytes of the generated encoding of wire_commands."""
    import numpy as np
    from support.memory_link import CaptureTransport

    from vtolftc.firmware_sim.autopilot.hil_bridge import HilBridge
    from vtolftc.protocols.hil import wire_commands
    from vtolftc.protocols.link import Link

    signing = SigningConfig(secret_key=bytes(range(32)), timestamp=10**9) if signed else None
    tr = CaptureTransport()
    bridge = HilBridge(Link(tr, system_id=1, component_id=1, signing=signing))
    ref = make_codec(1, 1, signing=signing)
    rng = np.random.default_rng(3)
    for k, n in enumerate((15, 15, 12, 15)):
        u = rng.uniform(-1.2, 1.2, n) / 3.0  # not float32-exact
        armed = k % 2 == 0
        bridge.send_controls(4000 * k, u, armed)
        slots = wire_commands(u).tolist() + [0.0] * (16 - n)
        want = ref.hil_actuator_controls_encode(4000 * k, slots, 128 if armed else 0,
                                                1).pack(ref)
        ref.seq = (ref.seq + 1) & 0xFF
        assert tr.sent[-1] == want
