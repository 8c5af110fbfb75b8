"""Rath's rolling filter on a surface that moves: the ball lands where the gap closes.

A ball launched with the impulse B (N over one sample) under its load W flies on the
parabola h(t) = u t - g t^2 / 2, u = B / (m fs), g = W / m; on a surface at rest it lands
at the ballistic time 2 u / g = 2 B / W samples (Rath, SDT), on a surface moving as X(t)
(positive away from the ball) once h(t) + X(t) - X(t_takeoff) <= 0.
"""

import math

import numpy as np
import pytest

from ugens.cells import slot
from ugens.driving_point import MODE_ROWS
from ugens.roll import (
    BALL_POINTS,
    GRAVITY,
    RollingConfig,
    RollingSetup,
    RollingState,
    SurfaceLaw,
    YieldingSurface,
    rolling_filter,
)

FS = 48000
MASS = 0.1  # kg
SPEED = 0.5  # m/s
TAKEOFF = 10  # the sample where the surface signal steps up


def fly(amplitude, freq, phase, rise=0.01, n=400):
    """Rath's filter over a surface signal with one step up (one take-off), the ball on a
    surface moving as X[n] = amplitude sin(2 pi freq n / fs + phase) (m; a lossless mode
    the ball's force does not move, and no contact spring) or, with amplitude None, on a
    rigid surface (no modes). Run one sample per call; returns the output force (N) and
    whether the ball is in the air after each sample (RollingState.airborne)."""
    x = np.zeros(n)
    x[TAKEOFF:] = rise
    config = RollingConfig(
        inv_dxfs=1.0, mass=MASS, grain=0.0005, depth=1000.0, has_input=1.0, cubic=0.0, smoothed=0.0,
        per_metre=0.0, unevenness=0.0,
    )  # fmt: skip
    setup = RollingSetup(
        np.zeros(4), np.zeros(5), np.array(config, dtype=np.float64), np.zeros(BALL_POINTS + 1)
    )
    if amplitude is None:
        modes = np.zeros((MODE_ROWS, 0))
    else:
        w = 2.0 * math.pi * freq / FS
        modes = np.array(
            [
                [2.0 * math.cos(w)],
                [1.0],
                [0.0],
                [amplitude * math.sin(phase - w)],
                [amplitude * math.sin(phase - 2 * w)],
            ]
        )
    law = np.array(SurfaceLaw(stiffness=0.0, gain_sum=0.0, mass_fs2=MASS * FS**2))
    out, contact = np.zeros(n), np.zeros(n)
    state = np.zeros(len(RollingState._fields))
    surface = YieldingSurface(modes, np.zeros(modes.shape[1]), law)
    forces, speeds = np.zeros(n), np.full(n, SPEED)
    airborne = np.zeros(n, dtype=bool)
    for i in range(n):
        at = slice(i, i + 1)
        rolling_filter(out[at], contact[at], 1, forces[at], speeds[at], x[at], state, setup, surface)
        airborne[i] = state[slot(RollingState, "airborne")] != 0.0
    return out, airborne


def landing(airborne):
    """The landing sample: the first after the take-off that ends with the ball down."""
    assert airborne[TAKEOFF] and not airborne[:TAKEOFF].any()
    return TAKEOFF + 1 + np.flatnonzero(~airborne[TAKEOFF + 1 :])[0]


def closed_form_landing(bump, amplitude, freq, phase):
    """First sample j after the take-off at which the parabola meets the moving surface."""
    u, g = bump / (MASS * FS), GRAVITY  # launch speed (m/s), the load's deceleration W / m
    t = np.arange(1, 400) / FS
    surface = amplitude * np.sin(2 * math.pi * freq * (TAKEOFF / FS + t) + phase)
    gap = u * t - 0.5 * g * t * t + surface - amplitude * math.sin(2 * math.pi * freq * TAKEOFF / FS + phase)
    return TAKEOFF + 1 + np.flatnonzero(gap <= 0.0)[0]


def test_a_surface_at_rest_gives_the_ballistic_flight():
    rigid, airborne = fly(None, 0.0, 0.0)
    bump = rigid[TAKEOFF]
    weight = MASS * GRAVITY
    assert landing(airborne) == TAKEOFF + math.ceil(2 * bump / weight)
    assert 10 < 2 * bump / weight < 100  # a flight of tens of samples
    np.testing.assert_allclose(fly(0.0, 700.0, 0.3)[0], rigid, rtol=0, atol=1e-12)


@pytest.mark.parametrize("phase", np.linspace(0.0, 2 * math.pi, 7, endpoint=False))
def test_the_ball_lands_when_the_surface_meets_it(phase):
    """A surface oscillating at 700 Hz, 1e-7 m (about the flight's height): the landing
    is the gap's closing, before or after the ballistic time depending on the phase, and
    the landing impulse stops the ball's own downward momentum m (g t - u) (none when
    the surface catches it still rising)."""
    amplitude, freq = 1e-7, 700.0
    out, airborne = fly(amplitude, freq, phase)
    bump = out[TAKEOFF]
    weight = MASS * GRAVITY
    land = landing(airborne)
    assert land == closed_form_landing(bump, amplitude, freq, phase)
    j = land - TAKEOFF
    assert out[land] == pytest.approx(max(0.0, weight * j - bump) - weight, abs=1e-9)


@pytest.mark.parametrize("phase", [0.4 * math.pi, 0.5 * math.pi])
def test_a_ball_caught_still_rising_lands_without_an_impulse(phase):
    """A surface coming up at 3e-7 m meets the ball before the top of its flight (j W < B;
    3 and 2 samples after the take-off of a 12-sample ballistic flight): it lands there,
    at the gap's closing, and its force that sample is -W, as in flight."""
    amplitude, freq = 3e-7, 700.0
    out, airborne = fly(amplitude, freq, phase)
    bump = out[TAKEOFF]
    weight = MASS * GRAVITY
    land = landing(airborne)
    assert land == closed_form_landing(bump, amplitude, freq, phase)
    assert weight * (land - TAKEOFF) < bump  # still rising
    assert out[land] == -weight


def test_landings_move_both_ways_with_the_surface():
    """Over the phases the surface meets the ball early (coming up) and late (moving away)."""
    ballistic = landing(fly(None, 0.0, 0.0)[1])
    lands = [landing(fly(1e-7, 700.0, p)[1]) for p in np.linspace(0.0, 2 * math.pi, 7, endpoint=False)]
    assert min(lands) < ballistic - 3 and max(lands) > ballistic + 3
