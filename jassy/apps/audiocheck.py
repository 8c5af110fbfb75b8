"""``jassy check-audio``: measure what a listener and a spectrum analyser would object to.

Each shipped patch (TOML) and physics scene is rendered at 48 kHz (patches without the
final limiter, so clipping is seen) and measured:

* subsonic share: the fraction of the signal's energy below 20 Hz (DC included), from the
  periodogram of the whole render; a loudspeaker radiates none of it;
* DC: the mean sample value, in units of full scale;
* clipping: samples with |x| > 1 before the limiter (scenes are normalised, so 0);
* aliasing: the power in the 16-24 kHz band of the 48 kHz render minus that of the same
  band of a render at 4x the rate (192 kHz), in dB (positive: energy folded back); not
  reported (None) when both bands lie below ALIAS_FLOOR of the total power;
* clicks: isolated spikes of the second difference (more than CLICK_RATIO times its RMS in
  the 0.5-10 ms before and after, and above 1e-3 of its peak) farther than CLICK_GUARD
  from any scheduled event. An impact excites ringing after its onset; a click does not.

Targets (:func:`failures`): subsonic share < 5 % (or the limit and reason a patch has in
SUBSONIC_EXCEPTIONS), |DC| < 1e-4, no clipped samples, and |aliasing| <= 1 dB for the
patches that must be band limited. Clicks are reported, not a target: sources that start
sounds by themselves (bubbles, crackle, firings, micro-impacts) make such onsets by design.
"""

from __future__ import annotations

import importlib
import tempfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

RATE = 48000
OVERSAMPLING = 4
SUBSONIC_HZ = 20.0
ALIAS_BAND = (16000.0, 24000.0)
#: Band power (relative to the total) under which the aliasing figure means nothing.
ALIAS_FLOOR = 1e-9
CLICK_RATIO = 10.0
CLICK_GUARD = 0.005
CLICK_NEAR = 0.0005
CLICK_FAR = 0.010

MAX_SUBSONIC = 0.05
#: Patches allowed more subsonic energy, with the reason: name -> (limit, why).
SUBSONIC_EXCEPTIONS = {
    "explosion": (0.10, "a blast wave's positive phase carries much of its energy below 20 Hz"),
}
MAX_DC = 1e-4
MAX_ALIAS_DB = 1.0
#: Patches whose high band must match the oversampled render.
BAND_LIMITED = ("engine", "crumple", "marble")


class AudioReport(NamedTuple):
    """Measures of one render (see the module docstring)."""

    name: str
    duration: float
    subsonic_share: float
    dc: float
    clipped: int
    alias_db: float | None
    clicks: int
    centroid_hz: float


class Render(NamedTuple):
    """Mono audio (frames,) at ``rate`` Hz and the times (s) of its scheduled events."""

    audio: np.ndarray
    rate: float
    event_times: np.ndarray


def subsonic_share(x: np.ndarray, rate: float, cutoff: float = SUBSONIC_HZ) -> float:
    """Fraction of sum(x^2) in periodogram bins below ``cutoff`` Hz (DC included)."""
    power = np.abs(np.fft.rfft(x)) ** 2
    power[1 : (x.size + 1) // 2] *= 2.0  # one-sided
    total = power.sum()
    if total <= 0:
        return 0.0
    freqs = np.fft.rfftfreq(x.size, 1.0 / rate)
    return float(power[freqs < cutoff].sum() / total)


def band_power(x: np.ndarray, rate: float, low: float, high: float) -> tuple[float, float]:
    """(power in [low, high) Hz, total power) from the periodogram, per sample."""
    power = np.abs(np.fft.rfft(x)) ** 2
    freqs = np.fft.rfftfreq(x.size, 1.0 / rate)
    band = power[(freqs >= low) & (freqs < high)].sum()
    return float(band), float(power.sum())


def centroid(x: np.ndarray, rate: float) -> float:
    """Spectral centroid (Hz) of the whole signal."""
    power = np.abs(np.fft.rfft(x)) ** 2
    total = power.sum()
    return float((np.fft.rfftfreq(x.size, 1.0 / rate) * power).sum() / total) if total > 0 else 0.0


def alias_db(x48: np.ndarray, rate: float, x_over: np.ndarray, rate_over: float) -> float | None:
    """Band power of ALIAS_BAND at ``rate`` over that at ``rate_over``, in dB (None if both
    are negligible). Powers are per second, so renders of equal length compare directly."""
    b1, t1 = band_power(x48, rate, *ALIAS_BAND)
    b2, t2 = band_power(x_over, rate_over, *ALIAS_BAND)
    # periodogram power scales with N^2; per-sample mean power is sum / N^2
    b1, t1 = b1 / x48.size**2, t1 / x48.size**2
    b2, t2 = b2 / x_over.size**2, t2 / x_over.size**2
    if b1 < ALIAS_FLOOR * t1 and b2 < ALIAS_FLOOR * t2:
        return None
    if b1 <= 0 or b2 <= 0:
        return float("inf") if b1 > b2 else float("-inf")
    return float(10.0 * np.log10(b1 / b2))


def _window_rms(e: np.ndarray, lo: int, hi: int, before: bool) -> np.ndarray:
    """RMS of e over [n + lo, n + hi) (after) or (n - hi, n - lo] (before), per n; zeros outside."""
    c = np.concatenate([[0.0], np.cumsum(e)])
    n = np.arange(e.size)
    if before:
        a, b = np.clip(n - hi + 1, 0, e.size), np.clip(n - lo + 1, 0, e.size)
    else:
        a, b = np.clip(n + lo, 0, e.size), np.clip(n + hi, 0, e.size)
    return np.sqrt((c[b] - c[a]) / (hi - lo))


def click_times(x: np.ndarray, rate: float, event_times=()) -> np.ndarray:
    """Times (s) of isolated spikes of the second difference away from ``event_times``."""
    if x.size < 3:
        return np.zeros(0)
    h = np.zeros(x.size)
    h[2:] = x[2:] - 2.0 * x[1:-1] + x[:-2]
    peak = np.max(np.abs(h))
    if peak <= 0:
        return np.zeros(0)
    e = h * h
    lo, hi = max(1, int(CLICK_NEAR * rate)), int(CLICK_FAR * rate)
    before = _window_rms(e, lo, hi, True)
    after = _window_rms(e, lo, hi, False)
    a = np.abs(h)
    spikes = np.flatnonzero((a > 1e-3 * peak) & (a > CLICK_RATIO * before) & (a > CLICK_RATIO * after))
    t = spikes / rate
    ev = np.sort(np.asarray(list(event_times), dtype=float))
    if ev.size and t.size:
        i = np.searchsorted(ev, t)
        near = np.full(t.size, np.inf)
        for j in (i - 1, i):
            ok = (j >= 0) & (j < ev.size)
            near[ok] = np.minimum(near[ok], np.abs(t[ok] - ev[j[ok]]))
        t = t[near > CLICK_GUARD]
    # a spike and its neighbours are one click
    if t.size:
        t = t[np.concatenate([[True], np.diff(t) > CLICK_NEAR])]
    return t


def measure(name: str, main: Render, over: Render | None, clipped: int) -> AudioReport:
    """The report of ``main`` (and of aliasing against ``over``, if given)."""
    x = main.audio
    return AudioReport(
        name=name,
        duration=x.size / main.rate,
        subsonic_share=subsonic_share(x, main.rate),
        dc=float(np.mean(x)) if x.size else 0.0,
        clipped=clipped,
        alias_db=alias_db(x, main.rate, over.audio, over.rate) if over is not None else None,
        clicks=int(click_times(x, main.rate, main.event_times).size),
        centroid_hz=centroid(x, main.rate),
    )


# ----------------------------------------------------------------------------- rendering
def shipped_names() -> list[str]:
    """Every built-in patch and scene, patches first."""
    from jassy.patchfile import builtin_patches
    from patches.scenes import SCENES

    return sorted(builtin_patches()) + sorted(SCENES)


def render_patch(name: str, rate: float, duration: float | None = None) -> tuple[Render, int]:
    """(mono render without the limiter, clipped sample count) of a TOML patch."""
    from jassy.engines.offline import OfflineEngine
    from jassy.patchfile import load_patch

    patch = load_patch(name)
    duration = duration or patch.duration or 4.0
    rendering = OfflineEngine(patch.graph, patch.score, rate, limiter=False).render(duration)
    audio = rendering.audio.mean(axis=0)
    clipped = int(np.count_nonzero(np.abs(rendering.audio) > 1.0))
    times = np.array([e.time for e in patch.score])
    return Render(audio, rate, times), clipped


def render_scene(name: str, rate: float, duration: float | None = None) -> tuple[Render, int]:
    """(mono render as written, 0) of a physics scene, with its score's event times."""
    from patches.scene_io import captured_renders
    from patches.scenes import SCENES

    module, function = SCENES[name]
    render = getattr(importlib.import_module(module), function)
    kwargs = {"duration": duration} if duration else {}
    with tempfile.TemporaryDirectory() as tmp, captured_renders() as renders:
        render(Path(tmp) / f"{name}.wav", None, None, sample_rate=int(rate), **kwargs)
    audio, score = renders[-1]
    return Render(audio.mean(axis=0), rate, np.array([e.time for e in score])), 0


def check(name: str, duration: float | None = None, aliasing: bool = True) -> AudioReport:
    """Render ``name`` (a patch or scene) and measure it."""
    from patches.scenes import SCENES

    renderer = render_scene if name in SCENES else render_patch
    main, clipped = renderer(name, RATE, duration)
    over = renderer(name, RATE * OVERSAMPLING, main.audio.size / RATE)[0] if aliasing else None
    return measure(name, main, over, clipped)


def failures(report: AudioReport) -> list[str]:
    """The targets ``report`` misses, one phrase each."""
    out = []
    limit = SUBSONIC_EXCEPTIONS.get(report.name, (MAX_SUBSONIC, ""))[0]
    if report.subsonic_share >= limit:
        out.append(f"subsonic share {report.subsonic_share:.1%} >= {limit:.0%}")
    if abs(report.dc) >= MAX_DC:
        out.append(f"DC {report.dc:.2e} >= {MAX_DC:g}")
    if report.clipped:
        out.append(f"{report.clipped} clipped samples")
    if report.name in BAND_LIMITED and report.alias_db is not None and abs(report.alias_db) > MAX_ALIAS_DB:
        out.append(f"16-24 kHz band {report.alias_db:+.1f} dB against the {OVERSAMPLING}x render")
    return out


def format_report(r: AudioReport) -> str:
    alias = "   n/a" if r.alias_db is None else f"{r.alias_db:+6.1f}"
    bad = failures(r)
    return (
        f"{r.name:<13} {r.duration:5.1f} s  subsonic {r.subsonic_share:6.1%}  DC {r.dc:+.1e}  "
        f"clipped {r.clipped:5d}  alias {alias} dB  clicks {r.clicks:3d}  centroid {r.centroid_hz:7.0f} Hz  "
        + ("FAIL: " + "; ".join(bad) if bad else "ok")
    )


def _cmd_check_audio(args) -> int:
    from jassy.errors import JassyError, suggest

    known = shipped_names()
    names = args.patch or known
    for name in names:
        if name not in known:
            raise JassyError(
                f"check-audio: unknown patch {name!r}; expected one of {', '.join(known)}"
                f"{suggest(name, known)}"
            )
    if args.duration is not None and not args.duration > 0:
        raise JassyError(f"--duration: expected seconds > 0, got {args.duration}")
    bad = 0
    for name in names:
        report = check(name, args.duration, aliasing=not args.no_alias)
        bad += bool(failures(report))
        print(format_report(report), flush=True)
    print(f"{len(names) - bad} of {len(names)} within the targets")
    return 1 if bad else 0


def add_command(sub) -> None:
    """Register ``jassy check-audio`` on an argparse sub-parser collection."""
    p = sub.add_parser(
        "check-audio",
        help="render shipped patches and scenes; report subsonic energy, DC, clipping, aliasing, clicks",
    )
    p.add_argument("patch", nargs="*", help="patch or scene names (default: all shipped)")
    p.add_argument("--duration", type=float, help="seconds to render (default: each patch's own)")
    p.add_argument("--no-alias", action="store_true", help="skip the 4x oversampled render")
    p.set_defaults(func=_cmd_check_audio)
