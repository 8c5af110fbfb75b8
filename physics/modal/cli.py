"""The ``jassy modes`` and ``jassy fit`` commands, and :func:`describe_model` for ``jassy info``.

Wire into ``jassy/apps/cli.py`` with ``add_commands(sub)`` on the argparse subparsers. Each
command is ``func(args) -> int`` and raises :class:`jassy.errors.JassyError` for bad input
(the CLI prints one line and exits 2). Heavy modules are imported inside the functions.

Examples::

    jassy modes bowl --material bronze -o bowl.toml --point rim=0.07,0,0.05
    jassy modes part.stl --scale 0.001 --material aluminium --modes 40 -o part.toml --surface part_surface.ply
    jassy fit strike.wav -o strike.toml --plot strike.png
    jassy fit a.wav b.wav c.wav -o plate.toml --fmax 12000     # one gain row per recording
    jassy fit taps.wav -o plate.toml --locations centre,edge   # one gain row per detected strike
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

from jassy.errors import JassyError

#: Procedural shapes accepted instead of a mesh file (see physics.modal.meshes).
SHAPES = ("bar", "plate", "bowl", "sphere")


def _check_output(path: str) -> None:
    from jassy.files import check_output

    check_output(path, "-o/--output", (".toml", ".npz"))


def _positive(name: str, value, integer: bool = False, allow_zero: bool = False) -> None:
    if value is None:
        return
    ok = value >= 0 if allow_zero else value > 0
    if not (ok and math.isfinite(value)):
        kind = "an integer" if integer else "a number"
        raise JassyError(f"{name}: expected {kind} {'>= 0' if allow_zero else '> 0'}, got {value}")


def parse_point(text: str) -> tuple[str, tuple[float, float, float]]:
    """``NAME=X,Y,Z`` (metres) -> (name, (x, y, z))."""
    name, sep, coords = text.partition("=")
    parts = coords.split(",")
    try:
        xyz = tuple(float(p) for p in parts)
    except ValueError:
        xyz = ()
    if not sep or not name.strip() or len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise JassyError(f"--point: expected NAME=X,Y,Z (metres), got {text!r}")
    return name.strip(), xyz  # type: ignore[return-value]


#: Most modes ``jassy modes`` computes.
MAX_MODES = 20000
#: Most Loop subdivisions of the gain surface (each multiplies its vertices by 4).
MAX_SUBDIVIDE = 8


def fem_bytes(elements: float, modes: int) -> float:
    """Estimated peak memory (bytes) of the voxel FEM solve for ``elements`` voxels and
    ``modes`` modes: about 35 KiB per element (stiffness, mass and the factor, whose fill
    grows like the cube root of the size; measured 0.1 GB at 2000 and 0.32 GB at 8000
    elements) plus the Krylov block of 4 vectors per mode over 3 dofs per element."""
    return 35e3 * elements * max(1.0, elements / 8000) ** (1 / 3) + 96.0 * modes * elements


def _check_modes_arguments(args: argparse.Namespace) -> dict:
    """Refuse bad ``jassy modes`` arguments before any work; return the ``--point`` locations."""
    _check_output(args.output)
    _positive("--modes", args.modes, integer=True)
    if args.modes > MAX_MODES:
        raise JassyError(f"--modes: expected an integer in [1, {MAX_MODES}], got {args.modes}")
    _positive("--pitch", args.pitch)
    _positive("--elements", args.elements, integer=True)
    _positive("--scale", args.scale)
    _positive("--fmax", args.fmax)
    if args.subdivide is not None and not 0 <= args.subdivide <= MAX_SUBDIVIDE:
        raise JassyError(f"--subdivide: expected an integer in [0, {MAX_SUBDIVIDE}], got {args.subdivide}")
    if args.pitch is not None and args.elements is not None:
        raise JassyError("--pitch and --elements: give one of them, not both")
    points = dict(parse_point(p) for p in args.point or ())
    if args.surface and points:
        raise JassyError("--surface: the sampled surface exists only without --point (a model per vertex)")
    if args.surface:
        from jassy.files import check_distinct, check_output

        check_output(args.surface, "--surface")
        check_distinct({"-o/--output": args.output, "--surface": args.surface})
    if not os.path.exists(args.mesh) and args.mesh not in SHAPES:
        raise JassyError(f"{args.mesh}: no such mesh file (or built-in shape: {', '.join(SHAPES)})")
    from jassy.limits import check_memory

    if args.elements is not None:
        check_memory(fem_bytes(args.elements, args.modes), f"--elements {args.elements}")
    return points


def _load_modes_mesh(args: argparse.Namespace):
    """The mesh to analyse: a built-in shape or a mesh file, scaled by ``--scale``."""
    from physics.modal import meshes

    if not os.path.exists(args.mesh) and args.mesh in SHAPES:
        mesh = getattr(meshes, args.mesh)()
        if args.scale != 1.0:
            mesh.apply_scale(args.scale)
        return mesh
    return meshes.load_mesh(args.mesh, args.scale)


def _plan_subdivision(args: argparse.Namespace, mesh, points: dict) -> int:
    """Subdivision steps of the sampled surface (``--subdivide`` or automatic), after checking
    the mesh encloses a volume and the FEM and surface fit in memory."""
    from jassy.limits import check_memory

    subdivide = args.subdivide
    if subdivide is None:  # auto: refine coarse meshes up to ~2000 control vertices (at most 3 times)
        subdivide, n = 0, len(mesh.vertices)
        while subdivide < 3 and n * 4 <= 2000 and not points:
            subdivide, n = subdivide + 1, n * 4
    try:
        volume = abs(float(mesh.volume))
    except (ZeroDivisionError, FloatingPointError, ValueError):
        volume = 0.0
    if not volume > 0:
        raise JassyError(f"{args.mesh}: the mesh encloses no volume (flat or degenerate); expected a solid")
    if args.pitch is not None:
        elements = volume / args.pitch**3
        check_memory(fem_bytes(elements, args.modes), f"--pitch {args.pitch:g} ({elements:.3g} elements)")
    surface_vertices = len(mesh.vertices) * 4.0**subdivide
    check_memory(
        surface_vertices * (args.modes * 32 + 1024),
        f"--subdivide {subdivide} ({surface_vertices:.3g} vertices)",
    )
    return subdivide


def _print_modes_summary(args: argparse.Namespace, model, report, surface, mat, seconds: float) -> None:
    """What ``jassy modes`` wrote: modes, band, material, time, the FEM report and notes."""
    print(
        f"wrote {args.output}: {model.n_modes} modes {model.frequencies.min():.1f}-"
        f"{model.frequencies.max():.1f} Hz, {model.n_points} location(s), {mat.name} "
        f"(E {mat.youngs:.3g} Pa, nu {mat.poisson:g}, rho {mat.density:g} kg/m^3) "
        f"in {seconds:.2f} s"
    )
    print(report.summary())
    if report.dropped_voxels:
        print(f"note: {report.dropped_voxels} voxel(s) not face-connected to the body were dropped")
    if report.families():
        print(report.families())
    if model.n_points > 2000 and args.output.lower().endswith(".toml"):
        print(f"note: {model.n_points} locations x {model.n_modes} modes; .npz is more compact than .toml")
    if args.surface:
        print(f"surface with {len(surface.vertices)} vertices (vertex i = model row i) -> {args.surface}")


def cmd_modes(args: argparse.Namespace) -> int:
    """``jassy modes MESH --material NAME -o MODEL``: finite element modes of a mesh."""
    points = _check_modes_arguments(args)
    from physics.modal.fem import modes_from_mesh
    from physics.modal.materials import material

    mat = material(
        args.material,
        youngs=args.youngs,
        poisson=args.poisson,
        density=args.density,
        loss=args.loss,
        d0=args.d0,
        beta=args.beta,
    )
    mesh = _load_modes_mesh(args)
    subdivide = _plan_subdivision(args, mesh, points)
    t0 = time.perf_counter()
    model, report, surface = modes_from_mesh(
        mesh,
        mat,
        n_modes=args.modes,
        pitch=args.pitch,
        elements=args.elements,
        subdivide=subdivide,
        points=points or None,
        radiation=args.radiation,
        normalise=args.normalise,
        name=args.name or os.path.splitext(os.path.basename(args.mesh))[0],
        f_max=args.fmax,
    )
    model.save(args.output)
    if args.surface:
        try:
            surface.export(args.surface)
        except Exception as exc:  # trimesh raises ValueError/KeyError for unknown formats
            raise JassyError(f"--surface: {args.surface}: cannot write mesh ({exc})") from None
    if not args.quiet:
        _print_modes_summary(args, model, report, surface, mat, time.perf_counter() - t0)
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    """``jassy fit REC.wav [REC2.wav ...] -o MODEL``: modes fitted to impact recordings."""
    _check_output(args.output)
    _positive("--modes", args.modes, integer=True)
    _positive("--fmin", args.fmin)
    _positive("--fmax", args.fmax)
    _positive("--margin", args.margin)
    _positive("--max-time", args.max_time)
    _positive("--onset", args.onset, allow_zero=True)
    _positive("--skip", args.skip, allow_zero=True)
    _positive("--duration", args.duration)
    if args.fmax is not None and args.fmax <= args.fmin:
        raise JassyError(f"--fmax: expected more than --fmin ({args.fmin:g} Hz), got {args.fmax:g}")
    if args.plot and os.path.splitext(args.plot)[1].lower() not in (".png", ".pdf", ".svg"):
        raise JassyError(f"--plot: {args.plot}: expected a .png, .pdf or .svg file name")
    if args.plot:
        from jassy.files import check_distinct, check_output
        from jassy.inputs import require_extra

        require_extra("matplotlib", "plot", "--plot")
        check_output(args.plot, "--plot")
        check_distinct({"-o/--output": args.output, "--plot": args.plot})
    for path in args.recordings:
        _check_recording(path, args.duration)

    import numpy as np

    from physics.modal.fit import fit_recordings, plot_fit, read_recording

    sigs, rates = [], []
    for path in args.recordings:
        x, rate = read_recording(path)
        sigs.append(x)
        rates.append(rate)
    if len(set(rates)) > 1:
        raise JassyError(f"recordings: expected one sample rate, got {sorted(set(rates))}")
    names = tuple(os.path.splitext(os.path.basename(p))[0] for p in args.recordings)
    if len(set(names)) != len(names):
        names = tuple(f"r{i}" for i in range(len(names)))
    locations = None
    if args.locations is not None:
        locations = tuple(n.strip() for n in args.locations.split(","))
        if not all(locations):
            raise JassyError(f"--locations: expected comma-separated names, got {args.locations!r}")
    show = not args.quiet and sys.stderr.isatty()
    if show:
        seconds = sum(len(x) for x in sigs) / rates[0]
        print(
            f"fitting {len(sigs)} recording(s), {seconds:.1f} s of audio (Ctrl-C stops) ...", file=sys.stderr
        )
    t0 = time.perf_counter()
    result = fit_recordings(
        sigs,
        rates[0],
        max_modes=args.modes,
        f_min=args.fmin,
        f_max=args.fmax,
        onset=args.onset,
        skip=args.skip,
        duration=args.duration,
        name=args.name or names[0],
        points=names,
        locations=locations,
        margin=args.margin,
        progress=show,
        time_limit=args.max_time,
    )
    model = result.model
    if args.normalise:
        model.gains = model.gains / np.max(np.abs(model.gains))
    model.save(args.output)
    if args.plot:
        plot_fit(result, sigs[0], args.plot)
    if not args.quiet:
        print(result.report())
        print(
            f"wrote {args.output}: {model.n_modes} modes in {time.perf_counter() - t0:.2f} s"
            + (f"; plot -> {args.plot}" if args.plot else "")
        )
    return 0


#: Longest recording analysed by ``jassy fit`` unless --max-seconds says otherwise (s): the
#: analysis costs far more per second of audio than rendering.
FIT_SECONDS = 60.0


def _check_recording(path: str, duration: float | None) -> None:
    """Before reading a recording: a regular audio file with a real sample rate, not longer
    (after --duration) than the fit limit, whose samples fit in the memory limit."""
    import soundfile

    from jassy.inputs import regular_file
    from jassy.limits import check_memory, check_seconds

    regular_file(path, "recording")
    try:
        info = soundfile.info(path)
    except Exception as exc:  # soundfile raises RuntimeError / LibsndfileError for non-audio
        raise JassyError(f"{path}: cannot read audio ({' '.join(str(exc).split())})") from None
    if not 1000 <= info.samplerate <= 768000:
        raise JassyError(f"{path}: sample rate {info.samplerate} Hz; expected 1000 to 768000 Hz")
    length = info.frames / info.samplerate
    check_seconds(min(length, duration or length), f"{path}", default=FIT_SECONDS)
    check_memory(info.frames * max(info.channels, 1) * 8 * 8, f"{path}")


def describe_model(path: str | os.PathLike) -> str:
    """A table of a model file's modes (for ``jassy info MODEL.toml``): frequency, decay rate,
    T60, Q, the multiplicity of degenerate families (m modes of one frequency), and the gains
    at up to six locations (else their maximum and mean magnitude); the stored attack."""
    import numpy as np

    from jassy.modal_model import ModalModel
    from physics.modal.fem import multiplicities

    m = ModalModel.load(path)
    lines = [
        f"model {m.name or os.path.basename(str(path))}: {m.n_modes} modes, "
        f"{m.frequencies.min():.1f}-{m.frequencies.max():.1f} Hz, {m.n_points} location(s)"
        + (f" ({', '.join(m.points)})" if m.points else ""),
        f"source: {path}",
    ]
    if m.attack is not None:
        lines.append(
            f"attack: {m.attack.size} samples "
            f"({1e3 * m.attack.size / m.attack_rate:.1f} ms at {m.attack_rate:g} Hz)"
        )
    multiplicity = multiplicities(m.frequencies)
    few = m.n_points <= 6
    if few:
        heads = [p for p in m.points] if m.points else [f"v{i}" for i in range(m.n_points)]
        gain_head = " ".join(f"{h[:10]:>10}" for h in heads)
    else:
        gain_head = f"{'max|a|':>10} {'mean|a|':>10}"
    lines.append(f"{'#':>4} {'f (Hz)':>10} {'m':>2} {'d (1/s)':>9} {'T60 (s)':>8} {'Q':>8}  {gain_head}")
    for k in range(m.n_modes):
        f, d = m.frequencies[k], m.decays[k]
        t60 = math.log(1000) / d if d > 0 else float("inf")
        q = math.pi * f / d if d > 0 else float("inf")
        col = m.gains[:, k]
        gains = (
            " ".join(f"{v:>10.4g}" for v in col)
            if few
            else f"{np.max(np.abs(col)):>10.4g} {np.mean(np.abs(col)):>10.4g}"
        )
        mult = f"{multiplicity[k]:>2}" if multiplicity[k] > 1 else "  "
        lines.append(f"{k:>4} {f:>10.2f} {mult} {d:>9.3f} {t60:>8.3f} {q:>8.0f}  {gains}")
    return "\n".join(lines)


def add_commands(subparsers) -> None:
    """Add ``modes`` and ``fit`` to the ``jassy`` argparse subparsers."""
    from physics.modal.materials import RADIATION

    p = subparsers.add_parser(
        "modes",
        help="compute a modal model from a mesh (finite elements)",
        description="Voxel finite element modes of a closed mesh: frequencies, material decays "
        "and gains on the surface (or at named points).",
    )
    p.add_argument(
        "mesh", help=f"mesh file (OBJ, STL, PLY, GLB, OFF, ...) or a built-in shape: {', '.join(SHAPES)}"
    )
    p.add_argument(
        "--material", default="steel", help="steel, aluminium, bronze, glass, wood, ceramic, plastic, bone"
    )
    p.add_argument("-o", "--output", required=True, help="model file (.toml or .npz)")
    p.add_argument("--modes", type=int, default=50, help="number of elastic modes (default 50)")
    p.add_argument("--pitch", type=float, help="voxel size in m (default: from --elements)")
    p.add_argument("--elements", type=int, help="target number of voxel elements (default 4000)")
    p.add_argument("--scale", type=float, default=1.0, help="multiply mesh coordinates (0.001 for mm)")
    p.add_argument("--youngs", type=float, metavar="PA", help="override Young's modulus (Pa)")
    p.add_argument("--poisson", type=float, help="override Poisson's ratio")
    p.add_argument("--density", type=float, metavar="KG_M3", help="override density (kg/m^3)")
    p.add_argument("--loss", type=float, metavar="ETA", help="override loss factor: d += pi eta f")
    p.add_argument("--d0", type=float, metavar="1/S", help="override constant decay rate (1/s)")
    p.add_argument(
        "--beta", type=float, metavar="S", help="stiffness Rayleigh damping: d += beta (2 pi f)^2 / 2"
    )
    p.add_argument(
        "--subdivide",
        type=int,
        help="Loop subdivisions of the gain surface (default: refine coarse meshes to ~2000 vertices)",
    )
    p.add_argument(
        "--point",
        action="append",
        metavar="NAME=X,Y,Z",
        help="a named strike point (m); repeat; the model then has one row per point",
    )
    p.add_argument(
        "--radiation",
        choices=RADIATION,
        default="displacement",
        help="gain = (n.phi)^2/omega x omega^r: displacement (default), velocity, acceleration",
    )
    p.add_argument("--normalise", action="store_true", help="scale gains so the loudest is 1")
    p.add_argument("--fmax", type=float, help="drop modes at or above this frequency (Hz)")
    p.add_argument(
        "--surface", metavar="FILE", help="write the sampled surface mesh (vertex i = model row i)"
    )
    p.add_argument("--name", help="model name (default: the mesh file's stem)")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_modes)

    p = subparsers.add_parser(
        "fit",
        help="fit a modal model to impact recordings",
        description="Frequencies, decay rates and gains of the modes in impact recordings "
        "(subspace estimation, ESPRIT, in sub-bands; strikes detected and pooled; clipped samples "
        "left out). Several recordings or channels share the modes and give one gain row each.",
    )
    p.add_argument("recordings", nargs="+", help="audio files (WAV, FLAC, ...)")
    p.add_argument("-o", "--output", required=True, help="model file (.toml or .npz)")
    p.add_argument("--modes", type=int, default=60, help="at most this many modes (default 60)")
    p.add_argument("--fmin", type=float, default=20.0, help="lowest frequency in Hz (default 20)")
    p.add_argument("--fmax", type=float, help="highest frequency in Hz (default: 20000 or 0.98 Nyquist)")
    p.add_argument(
        "--margin",
        type=float,
        default=4.0,
        help="how far a mode's subspace eigenvalue must exceed the noise edge (default 4)",
    )
    p.add_argument(
        "--locations",
        metavar="A,B,...",
        help="name each detected strike (in order): one gain row per strike, a texture map of the hits",
    )
    p.add_argument(
        "--max-time", type=float, default=300.0, help="stop the fit after this many seconds (default 300)"
    )
    p.add_argument("--onset", type=float, help="impact time in s (default: strikes detected)")
    p.add_argument("--skip", type=float, default=0.0, help="seconds after the onset left out (contact)")
    p.add_argument("--duration", type=float, help="seconds analysed after the onset (default: all)")
    p.add_argument("--normalise", action="store_true", help="scale gains so the loudest is 1")
    p.add_argument(
        "--plot", metavar="PNG", help="spectrograms of recording, resynthesis, residual (matplotlib)"
    )
    p.add_argument("--name", help="model name (default: the first recording's stem)")
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=cmd_fit)
