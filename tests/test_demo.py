"""The probe demo driven headless by a scripted path (the window uses the same Probe)."""

import numpy as np
import pytest

from jassy import JassyError
from patches.demo import PRESS_FORCE, TAP_IMPULSE, Probe, render_script, stroke

FS = 48000


@pytest.mark.parametrize("mode", ["scrape", "roll"])
def test_scripted_stroke_taps_then_slides_then_stops(mode):
    r = render_script(stroke(0.2, 1.2), 2.0, mode)
    force, audio = r.haptic[0], r.audio[0]
    press = int(0.2 * FS)
    assert np.all(force[:press] == 0) and np.all(audio[:press] == 0)
    # the tap: an impulse of TAP_IMPULSE on top of the pressing force, at the press
    assert np.flatnonzero(force)[0] == press + 1
    # while dragging, the contact force fluctuates (the surface profile) and is never silent
    drag = force[int(0.4 * FS) : int(1.1 * FS)]
    assert drag.std() > 0 and np.mean(np.abs(drag)) > 0
    # after the release ramp the probe no longer touches: no force, the plate rings down
    assert np.all(force[int(1.3 * FS) :] == 0)
    late = np.sqrt(np.mean(audio[int(1.8 * FS) :] ** 2))
    assert late < np.sqrt(np.mean(audio[int(0.5 * FS) : int(1.0 * FS)] ** 2))


def test_a_faster_drag_scrapes_brighter():
    def centroid(x):
        spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size)))
        freqs = np.fft.rfftfreq(x.size, 1 / FS)
        return float(np.sum(freqs * spectrum) / np.sum(spectrum))

    slow = render_script(stroke(0.1, 1.1, 0.4, 0.5), 1.2).haptic[0][int(0.4 * FS) : int(1.0 * FS)]
    fast = render_script(stroke(0.1, 1.1, 0.0, 1.0), 1.2).haptic[0][int(0.4 * FS) : int(1.0 * FS)]
    assert centroid(fast) > 1.5 * centroid(slow)


def test_probe_events_and_location_map():
    sent = []
    probe = Probe(sent.append)
    probe.press(0.5, 1.0)
    probe.move(0.6, 1.1)
    probe.release(1.2)
    actions = [(e.node, e.action) for e in sent]
    assert ("tap", "impact") in actions and sent[1].args["impulse"] == TAP_IMPULSE
    assert sent[2].args["force"] == PRESS_FORCE
    speed = next(e for e in sent if e.node == "contact" and "speed" in e.args and e.ramp).args["speed"]
    assert speed == pytest.approx(0.1 * probe.width / 0.1)
    assert probe.location(0.5) == {"vertices": ["t4", "t5"], "weights": [1.0, 0.0]}
    assert probe.location(1.0)["vertices"] == ["t7", "t8"]
    with pytest.raises(JassyError, match="unknown action 'hover'"):
        render_script([(0.0, "hover", 0.5)], 0.1)


def test_drill_mode_cuts_bone_while_the_button_is_held():
    from patches.demo import render_drill_script

    r, probe = render_drill_script([(0.2, "press", 0.5), (1.2, "release", 0.5)], 1.6)
    force, audio = r.haptic[0], r.audio[0]
    assert np.all(force[: int(0.2 * FS)] == 0)  # nothing touches before the press
    assert np.mean(np.abs(force[int(0.7 * FS) : int(1.1 * FS)])) > 0.1  # pushing into bone, N
    assert np.all(force[int(1.35 * FS) :] == 0)  # lifted after the release ramp
    assert probe.removed > 0  # bone was cut
    rms = lambda a, b: np.sqrt(np.mean(audio[int(a * FS) : int(b * FS)] ** 2))  # noqa: E731
    assert rms(0.7, 1.1) > 3 * rms(0.0, 0.15)  # drilling is louder than the idle handpiece
    assert np.max(np.abs(audio)) < 1.0
