"""Live contacts: attack, ramps, latest-wins moves, release, transients, validation.

Contacts are placed on actuators (a gain of 1 on one channel) or between two, so each
channel's output is the carrier times a known gain; the carrier is the renderer's own
source, started at the touchdown frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from phantomtouch import DeviceProfile, EngineBusyError, ParameterError, ProtocolError, gains_at
from phantomtouch.engine import ContactSettings, Engine
from phantomtouch.engine.future_mix import AHEAD_FRAMES
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.renderer.carriers import NoiseSource, SineSource
from phantomtouch.renderer.levels import amplitude_for_level
from phantomtouch.schema import NoiseCarrier, SineCarrier

DEVICE = DeviceProfile.default()
RATE = DEVICE.sample_rate_hz
BLOCK = DEVICE.block_frames
ATTACK = round(0.01 * RATE)
RELEASE = round(0.08 * RATE)
HALF = amplitude_for_level(DEVICE.safety.max_level_db + 20 * math.log10(0.5), DEVICE)
FLOAT32 = 1e-7
"""Gains, ramps and envelopes are float32: a few ulps of 1 (6e-8), times an amplitude < 1."""


def sine(frames: int, offset: int = 0) -> np.ndarray:
    return SineSource(100.0, RATE).block(offset, frames).astype(np.float64)


@pytest.fixture
def captured() -> Iterator[tuple[Engine, CaptureSink]]:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        yield engine, sink


def test_touchdown_fades_in_over_the_attack_from_its_sample(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    down = 3 * BLOCK + 17
    engine.contact_down("c", "f", 0.0, 4.8, intensity=0.5, at_frame=down)  # actuator 2
    recording = sink.pull(8).astype(np.float64)
    n = len(recording) - down
    attack = np.minimum(1.0, np.arange(1, n + 1) / ATTACK)
    assert not np.any(recording[:down])
    np.testing.assert_allclose(recording[down:, 1], HALF * attack * sine(n), atol=FLOAT32)
    assert not np.any(np.delete(recording, 1, axis=1))  # only the driven channel is touched


def test_a_move_ramps_the_gains_linearly_across_the_next_block(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 0.0, intensity=0.5, at_frame=0)  # actuator 1
    sink.pull(4)
    engine.contact_move("c", "f", 0.0, 4.8)  # to actuator 2
    block = sink.pull(2).astype(np.float64)
    ramp = np.arange(1, BLOCK + 1) / BLOCK
    carrier = sine(2 * BLOCK, 4 * BLOCK)
    np.testing.assert_allclose(block[:BLOCK, 0], HALF * (1 - ramp) * carrier[:BLOCK], atol=FLOAT32)
    np.testing.assert_allclose(block[:BLOCK, 1], HALF * ramp * carrier[:BLOCK], atol=FLOAT32)
    np.testing.assert_allclose(block[BLOCK:, 1], HALF * carrier[BLOCK:], atol=FLOAT32)
    assert not np.any(block[BLOCK:, 0])


def test_a_contact_across_the_band_moves_with_its_gains_and_leaves_the_rest_silent(
    captured: tuple[Engine, CaptureSink],
) -> None:
    # Between actuators 1 and 5 (channels 1 and 5), then between 2 and 6: the driven
    # channels span more than half the band, which the voice adds all at once.
    engine, sink = captured
    engine.contact_down("c", "f", 1.9, 0.0, intensity=0.5, at_frame=0)
    sink.pull(4)
    engine.contact_move("c", "f", 1.9, 4.8)
    block = sink.pull(2).astype(np.float64)
    ramp = np.arange(1, BLOCK + 1) / BLOCK
    carrier = sine(2 * BLOCK, 4 * BLOCK)
    before, after = gains_at(DEVICE, 1.9, 0.0), gains_at(DEVICE, 1.9, 4.8)
    assert np.count_nonzero(before) == np.count_nonzero(after) == 2
    gains = before + ramp[:, None] * (after - before)
    np.testing.assert_allclose(block[:BLOCK], HALF * gains * carrier[:BLOCK, None], atol=FLOAT32)
    np.testing.assert_allclose(block[BLOCK:], HALF * after * carrier[BLOCK:, None], atol=FLOAT32)
    assert not np.any(block[:, before + after == 0])


def test_latest_position_wins_and_nothing_queues_up(captured: tuple[Engine, CaptureSink]) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 0.0, intensity=0.5, at_frame=0)
    sink.pull(4)
    for y_cm in (14.4, 9.6, 4.8):  # only the last arrives before the next block
        engine.contact_move("c", "f", 0.0, y_cm)
    block = sink.pull(3)
    assert not np.any(block[:, [2, 3]])  # actuators 3 and 4 never sound
    assert np.abs(block[BLOCK:, 1]).max() > 0.9 * HALF
    assert engine.status().late_commands == 0


def test_a_move_for_a_later_frame_waits_for_its_block(captured: tuple[Engine, CaptureSink]) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 0.0, intensity=0.5, at_frame=0)
    sink.pull(4)
    engine.contact_move("c", "f", 0.0, 4.8, at_frame=7 * BLOCK + 3)
    recording = sink.pull(5)
    assert not np.any(recording[: 3 * BLOCK, 1])  # blocks 4-6: still at actuator 1
    assert np.any(recording[3 * BLOCK : 4 * BLOCK, 1])  # block 7 ramps towards actuator 2
    assert not np.any(recording[4 * BLOCK :, 0])


def test_lift_off_fades_out_and_is_silent_within_the_release(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 3.8, 9.6, intensity=0.5, at_frame=0)  # actuator 7
    sink.pull(4)
    up = 6 * BLOCK + 100
    engine.contact_up("c", "f", at_frame=up)
    recording = sink.pull(4 + RELEASE // BLOCK).astype(np.float64)
    frames = np.arange(4 * BLOCK, 4 * BLOCK + len(recording))
    fade = np.clip((up + RELEASE - 1 - frames) / RELEASE, 0.0, 1.0)
    expected = HALF * fade * sine(len(recording), 4 * BLOCK)
    np.testing.assert_allclose(recording[:, 6], expected, atol=FLOAT32)
    assert not np.any(recording[up + RELEASE - 1 - 4 * BLOCK :])
    assert engine.status().active_voices == 0


def test_lift_off_during_the_attack_fades_from_the_level_reached(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 4.8, intensity=0.5, at_frame=0)
    up = ATTACK // 2
    engine.contact_up("c", "f", at_frame=up)
    recording = sink.pull(2 + RELEASE // BLOCK).astype(np.float64)
    frames = np.arange(len(recording))
    level = np.minimum(np.minimum(1.0, (frames + 1) / ATTACK), 0.5 - (frames - up + 1) / RELEASE)
    expected = HALF * np.clip(level, 0.0, None) * sine(len(recording))
    np.testing.assert_allclose(recording[:, 1], expected, atol=FLOAT32)
    assert not np.any(recording[up - 1 + RELEASE // 2 :])


def test_an_impact_transient_is_a_decaying_sinusoid_scaled_by_the_velocity() -> None:
    def play(down_m_s: float | None, up_m_s: float | None) -> np.ndarray:
        sink = CaptureSink(DEVICE)
        with Engine(DEVICE, sink) as engine:
            engine.contact_down(
                "c", "f", 0.0, 2.4, intensity=0.5, normal_velocity_m_s=down_m_s, at_frame=50
            )
            engine.contact_up("c", "f", normal_velocity_m_s=up_m_s, at_frame=20 * BLOCK)
            return sink.pull(30 + RELEASE // BLOCK).astype(np.float64)

    plain, struck = play(None, None), play(0.25, -1.0)
    burst = struck - plain
    settings = ContactSettings()
    full = amplitude_for_level(DEVICE.safety.max_level_db + 20 * math.log10(0.5), DEVICE)
    t = np.arange(math.ceil(7 * settings.transient_decay_s * RATE)) / RATE
    shape = np.exp(-t / settings.transient_decay_s) * np.sin(2 * np.pi * 250.0 * t)
    unit = np.sqrt(0.5)  # halfway between actuators 1 and 2: power law
    for at, scale in ((50, 0.5), (20 * BLOCK, 1.0)):  # 0.25 of 0.5 m/s; |-1| m/s saturates
        for channel in (0, 1):
            np.testing.assert_allclose(
                burst[at : at + len(t), channel], scale * full * unit * shape, atol=2e-7
            )
    burst[50 : 50 + len(t)] = 0.0
    burst[20 * BLOCK : 20 * BLOCK + len(t)] = 0.0
    assert np.abs(burst).max() < 1e-7  # nothing else changed


def test_a_noise_contact_plays_the_renderers_noise(captured: tuple[Engine, CaptureSink]) -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, contact=ContactSettings(attack_s=0.0)) as engine:
        carrier = NoiseCarrier(low_hz=60.0, high_hz=300.0, seed=11)
        engine.contact_down("c", "f", 3.8, 0.0, intensity=0.5, carrier=carrier, at_frame=300)
        recording = sink.pull(6)
    noise = NoiseSource(60.0, 300.0, 11, RATE).block(0, len(recording) - 300)
    np.testing.assert_array_equal(recording[300:, 4], noise * np.float32(HALF))
    assert not np.any(np.delete(recording, 4, axis=1))


def test_default_intensity_is_table_i_low(captured: tuple[Engine, CaptureSink]) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 9.6, carrier=SineCarrier(freq_hz=150.0), at_frame=0)
    recording = sink.pull(40)
    low = amplitude_for_level(131.0, DEVICE)  # Table I: 150 Hz, low
    assert np.abs(recording[ATTACK:, 2]).max() == pytest.approx(low, rel=1e-4)


def test_positions_outside_the_layout_are_projected_onto_it() -> None:
    def play(x_cm: float, y_cm: float) -> np.ndarray:
        sink = CaptureSink(DEVICE)
        with Engine(DEVICE, sink) as engine:
            engine.contact_down("c", "f", x_cm, y_cm, intensity=0.3, at_frame=0)
            return sink.pull(5)

    np.testing.assert_array_equal(play(-3.0, 20.0), play(0.0, 14.4))
    np.testing.assert_array_equal(play(1.9, -2.0), play(1.9, 0.0))


def test_a_second_touchdown_replaces_the_contact(captured: tuple[Engine, CaptureSink]) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 0.0, 0.0, intensity=0.5, at_frame=0)
    sink.pull(4)
    engine.contact_down("c", "f", 3.8, 14.4, intensity=0.5)
    sink.pull(1)
    assert engine.status().active_voices == 2
    assert engine.status().active_contacts == [
        {"owner": "c", "contact": "f", "x_cm": 3.8, "y_cm": 14.4}
    ]
    recording = sink.pull(RELEASE // BLOCK + 1)
    assert not np.any(recording[-BLOCK:, 0])
    assert engine.status().active_voices == 1


def test_contacts_past_the_limit_are_refused() -> None:
    with Engine(DEVICE, CaptureSink(DEVICE), contact=ContactSettings(max_contacts=2)) as engine:
        engine.contact_down("a", "1", 1.0, 1.0)
        engine.contact_down("b", "1", 1.0, 1.0)
        engine.contact_down("b", "1", 2.0, 2.0)  # replacing one is fine
        with pytest.raises(EngineBusyError, match="max_contacts=2"):
            engine.contact_down("a", "2", 1.0, 1.0)  # a holder of one, all others hold one
        engine.contact_down("c", "1", 1.0, 1.0)  # a newcomer always gets one: the oldest yields
        assert engine.contacts_of("c") == ["1"] and engine.contacts_of("a") == []


@pytest.mark.parametrize(
    ("arguments", "field"),
    [
        ({"x_cm": float("nan")}, "x_cm=nan"),
        ({"y_cm": float("inf")}, "y_cm=inf"),
        ({"x_cm": 1e6}, "x_cm=1000000.0"),
        ({"intensity": 1.5}, "intensity=1.5"),
        ({"intensity": -0.1}, "intensity=-0.1"),
        ({"law": "cubic"}, "law='cubic'"),
        ({"contact": ""}, "contact=''"),
        ({"contact": "x" * 65}, "contact='xxx"),
        ({"owner": 7}, "owner=7"),
        ({"at_frame": -5}, "at_frame=-5"),
        ({"normal_velocity_m_s": float("nan")}, "normal_velocity_m_s=nan"),
        ({"carrier": SineCarrier(freq_hz=30000.0)}, "carrier.freq_hz=30000.0"),
        ({"carrier": NoiseCarrier(low_hz=40.0, high_hz=22000.0)}, "carrier.high_hz=22000.0"),
        (  # a band of a few steps of the noise loop is a few beating sines, not noise
            {"carrier": NoiseCarrier(low_hz=1.0, high_hz=1.2)},
            "carrier.low_hz=1.0, carrier.high_hz=1.2",
        ),
    ],
)
def test_bad_touchdowns_are_refused_naming_the_field(
    captured: tuple[Engine, CaptureSink], arguments: dict[str, object], field: str
) -> None:
    engine, _ = captured
    call: dict[str, object] = {"owner": "c", "contact": "f", "x_cm": 1.0, "y_cm": 1.0}
    call.update(arguments)
    with pytest.raises(ParameterError, match=f"^{field}"):
        engine.contact_down(**call)  # type: ignore[arg-type]
    assert engine.status().active_contacts == []


def test_moves_need_a_contact_that_is_down_and_up_is_idempotent(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, _ = captured
    with pytest.raises(ProtocolError, match="expected down, got move"):
        engine.contact_move("c", "f", 1.0, 1.0)
    engine.contact_up("c", "f")
    engine.contact_down("c", "f", 1.0, 1.0)
    with pytest.raises(ParameterError, match=r"^x_cm=nan"):
        engine.contact_move("c", "f", float("nan"), 1.0)
    with pytest.raises(ParameterError, match=r"^intensity=2"):
        engine.contact_move("c", "f", 1.0, 1.0, intensity=2)


def test_contact_gains_are_the_renderers_phantom_gains(
    captured: tuple[Engine, CaptureSink],
) -> None:
    engine, sink = captured
    engine.contact_down("c", "f", 1.3, 6.1, intensity=0.5, law="linear", at_frame=0)
    recording = sink.pull(8).astype(np.float64)
    carrier = sine(len(recording))
    gains = gains_at(DEVICE, 1.3, 6.1, law="linear") * HALF
    tail = slice(ATTACK, None)
    np.testing.assert_allclose(recording[tail], carrier[tail, None] * gains, atol=FLOAT32)


@pytest.mark.parametrize(
    ("field", "value"),
    [("attack_s", -1.0), ("release_s", 0.0), ("transient_freq_hz", 0.0), ("max_contacts", 0)],
)
def test_contact_settings_refuse_nonsense(field: str, value: float) -> None:
    with pytest.raises(ParameterError, match=f"^{field}="):
        ContactSettings(**{field: value})  # type: ignore[arg-type]


def test_contacts_moved_in_one_block_each_ramp_to_their_gains_and_add_up(
    captured: tuple[Engine, CaptureSink],
) -> None:
    """Contacts sound together as one array operation: their sum is each one's carrier
    times its own gains ramped across the block."""
    engine, sink = captured
    moves = {
        "a": ((0.0, 0.0), (3.8, 9.6)),
        "b": ((1.0, 6.0), (0.5, 1.0)),
        "c": ((3.8, 14.4), (2.0, 12.0)),
    }
    for name, (before, _) in moves.items():
        engine.contact_down("c", name, *before, intensity=0.5, at_frame=0)
    sink.pull(4)
    for name, (_, after) in moves.items():
        engine.contact_move("c", name, *after)
    block = sink.pull(2).astype(np.float64)
    ramp = np.arange(1, BLOCK + 1) / BLOCK
    carrier = sine(2 * BLOCK, 4 * BLOCK)
    expected = np.zeros((2 * BLOCK, DEVICE.channels))
    for before, after in moves.values():
        old, new = gains_at(DEVICE, *before), gains_at(DEVICE, *after)
        expected[:BLOCK] += HALF * (old + ramp[:, None] * (new - old)) * carrier[:BLOCK, None]
        expected[BLOCK:] += HALF * new * carrier[BLOCK:, None]
    # three float32 gains and carriers, summed: a few ulps of the amplitude
    np.testing.assert_allclose(block, expected, atol=3 * FLOAT32)


def test_sine_and_noise_contacts_sounding_together_each_keep_their_carrier() -> None:
    """The sine carriers among the contacts are computed together and put back in their
    contacts' rows: a noise contact between two sines keeps its noise, each at its gains."""
    sink = CaptureSink(DEVICE)
    noise_carrier = NoiseCarrier(low_hz=60.0, high_hz=300.0, seed=11)
    places = {"a": (0.0, 0.0), "b": (3.8, 9.6), "c": (2.0, 12.0)}
    with Engine(DEVICE, sink, contact=ContactSettings(attack_s=0.0)) as engine:
        engine.contact_down("c", "a", *places["a"], intensity=0.5, at_frame=0)
        engine.contact_down(
            "c", "b", *places["b"], intensity=0.5, carrier=noise_carrier, at_frame=0
        )
        engine.contact_down("c", "c", *places["c"], intensity=0.5, at_frame=0)
        recording = sink.pull(6).astype(np.float64)
    frames = len(recording)
    carriers = {
        "a": sine(frames),
        "b": NoiseSource(60.0, 300.0, 11, RATE).block(0, frames).astype(np.float64),
        "c": sine(frames),
    }
    expected = np.zeros((frames, DEVICE.channels))
    for name, place in places.items():
        expected += HALF * gains_at(DEVICE, *place) * carriers[name][:, None]
    np.testing.assert_allclose(recording, expected, atol=3 * FLOAT32)


def test_sine_carriers_computed_ahead_are_each_contacts_sine_bit_for_bit() -> None:
    """Sine carriers are computed ``AHEAD_FRAMES`` at a time into each contact: across
    several such stretches, begun at frames of their own, each contact's channel is its
    sine times its float32 gain, bit for bit (one contact a channel: the float64 product
    rounded once is the float32 product)."""
    sink = CaptureSink(DEVICE)
    downs = {"a": ((0.0, 0.0), 0, 300), "b": ((3.8, 14.4), 7, 300 + AHEAD_FRAMES // 3)}
    with Engine(DEVICE, sink, contact=ContactSettings(attack_s=0.0)) as engine:
        for name, ((x_cm, y_cm), _, frame) in downs.items():
            engine.contact_down("c", name, x_cm, y_cm, intensity=0.5, at_frame=frame)
        recording = sink.pull(-(-4 * AHEAD_FRAMES // BLOCK))
    for _, channel, frame in downs.values():
        carrier = SineSource(100.0, RATE).block(0, len(recording) - frame)
        np.testing.assert_array_equal(recording[frame:, channel], carrier * np.float32(HALF))
        assert not np.any(recording[:frame, channel])


TOUCHES = ((8 * BLOCK, 9 * BLOCK), (20 * BLOCK + 17, 40 * BLOCK + 5))
"""Frames where another contact touches down and is lifted: on a block's start, lifted
during its attack; then mid-block, lifted after its attack and after the steady
contact's sines ran out once."""


def test_a_contact_keeps_its_sine_while_others_touch_down_fade_and_lift_off() -> None:
    """A steady contact's carrier stays its own sine, bit for bit, across blocks where
    another contact touches down, fades in, sounds through, is lifted and fades out: the
    blocks where every contact sounds plainly through and those where one fades or renders
    alone take the carriers two ways, and neither may shift or repeat the steady
    contact's samples (one contact a channel, as above)."""
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        engine.contact_down("c", "a", 0.0, 0.0, intensity=0.5, at_frame=0)
        for down, up in TOUCHES:
            engine.contact_down("c", "b", 3.8, 14.4, intensity=0.5, at_frame=down)
            engine.contact_up("c", "b", at_frame=up)
        recording = sink.pull(8 * AHEAD_FRAMES // BLOCK)
    carrier = SineSource(100.0, RATE).block(0, len(recording))
    np.testing.assert_array_equal(recording[ATTACK:, 0], carrier[ATTACK:] * np.float32(HALF))
    (first_down, first_up), (second_down, second_up) = TOUCHES
    assert not np.any(recording[:first_down, 7])
    assert np.any(recording[first_down:first_up, 7])
    assert not np.any(recording[first_up + RELEASE : second_down, 7])
    assert np.any(recording[second_down:second_up, 7])
    assert not np.any(recording[second_up + RELEASE :, 7])
