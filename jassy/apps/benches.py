"""The benches of ``jassy bench NAME``: one table, one line per bench.

A bench is a function of the parsed command line that measures and prints a table (JSON with
``--json``). To add one, write its function here (or import it) and add a line to
:data:`BENCHES`; the command's choices and help come from the table.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import NamedTuple


class Bench(NamedTuple):
    """One ``jassy bench`` choice: what it runs and its line of help."""

    run: Callable[[argparse.Namespace], None]
    help: str


def _say(name: str) -> Callable[[str], None]:
    """Progress lines ``bench NAME: message ...`` on stderr."""

    def say(message: str) -> None:
        print(f"bench {name}: {message} ...", file=sys.stderr, flush=True)

    return say


def _modal(args: argparse.Namespace) -> None:
    from jassy.apps import bench

    counts = (64, 1024) if args.quick else (64, 1024, 16384)
    rows = bench.modal_bench(counts, seconds=0.25 if args.quick else 1.0)
    graph = bench.graph_bench(seconds=2.0 if args.quick else 10.0)
    if args.json:
        print(json.dumps({"modal": rows, "graph": graph}, indent=2))
    else:
        bench.print_modal(rows, graph)


def _float32(args: argparse.Namespace) -> None:
    from jassy.apps.bench_f32 import float32_bench, print_float32

    rows = float32_bench(rounds=2 if args.quick else 5, repeats=10 if args.quick else 40)
    print(json.dumps(rows, indent=2)) if args.json else print_float32(rows)


def _contact(args: argparse.Namespace) -> None:
    from jassy.apps import bench

    rows = bench.contact_bench()
    print(json.dumps(rows, indent=2)) if args.json else bench.print_contact(rows)


def _live(args: argparse.Namespace) -> None:
    from jassy.apps import bench

    result = bench.live_bench(
        seconds=args.seconds or 60.0,
        block=args.block,
        ring_blocks=args.ring,
        mode=args.mode,
        floor=args.floor,
    )
    print(json.dumps(result, indent=2)) if args.json else bench.print_live(result)


def _batch(args: argparse.Namespace) -> None:
    from jassy.batch import bench_batch, print_bench

    result = bench_batch(duration=1.0, repeats=1) if args.quick else bench_batch()
    print(json.dumps(result, indent=2)) if args.json else print_bench(result)


def _burr(args: argparse.Namespace) -> None:
    from physics.burr.bench import bench_burr, print_burr

    rows = bench_burr(n=128 if args.quick else 256)
    print(json.dumps(rows, indent=2)) if args.json else print_burr(rows)


def _rigid(args: argparse.Namespace) -> None:
    from patches.wok_bench import wok_rows
    from physics.rigid.bench import bench_rigid, print_rigid
    from physics.rigid.pile_bench import bench_piles, print_piles
    from physics.rigid.solver_bench import bench_solvers, print_solvers

    say = _say("rigid")
    rows = bench_rigid(quick=args.quick, progress=say)
    say("wok scene: physics alone and the full render")
    rows += wok_rows(2.0 if args.quick else 6.0)
    piles = bench_piles((10, 100) if args.quick else (100, 1000), progress=say)
    say("solvers: ABA, Lemke, PGS")
    solvers = bench_solvers(quick=args.quick)
    if args.json:
        print(json.dumps({"world": rows, "mujoco": piles, "solvers": solvers}, indent=2))
    else:
        print_rigid(rows), print_piles(piles), print_solvers(solvers)


def _deform(args: argparse.Namespace) -> None:
    from physics.deform.bench import bench_deform, print_deform
    from physics.deform.cataract_bench import bench_cataract, print_cataract

    rows, cataract = bench_deform(quick=args.quick), bench_cataract(quick=args.quick)
    if args.json:
        print(json.dumps({"bem": rows, "cataract": cataract}, indent=2))
    else:
        print_deform(rows), print_cataract(cataract)


def _rod(args: argparse.Namespace) -> None:
    from physics.modal._blas import single_threaded
    from physics.rod.bench import bench_rod, print_rod
    from physics.rod.contact_bench import bench_rod_contact, print_rod_contact
    from physics.rod.dfcp_bench import bench_dfcp, print_dfcp

    with single_threaded():
        rows = bench_rod(quick=args.quick)
        contact = bench_rod_contact(quick=args.quick)
        dfcp = bench_dfcp()
    if args.json:
        print(json.dumps({"models": rows, "contact": contact, "dfcp": dfcp}, indent=2))
    else:
        print_rod(rows), print_rod_contact(contact), print_dfcp(dfcp)


def _startup(args: argparse.Namespace) -> None:
    from jassy.apps.startup import bench_startup, print_startup

    rows = bench_startup(("bell",) if args.quick else ("bell", "wok"), progress=_say("startup"))
    print(json.dumps(rows, indent=2)) if args.json else print_startup(rows)


def _anytime(args: argparse.Namespace) -> None:
    from jassy.apps.anytime_bench import bench_anytime, plot_anytime, print_anytime

    if args.plot:
        from jassy.apps.preview import check_png, require_matplotlib

        require_matplotlib("--plot")
        check_png(args.plot, "--plot")
    result = bench_anytime(quick=args.quick)
    print(json.dumps(result, indent=2)) if args.json else print_anytime(result)
    if args.plot:
        plot_anytime(result, args.plot)


def _fit(args: argparse.Namespace) -> None:
    from physics.modal._blas import single_threaded
    from physics.modal.fit_bench import bench_fit, fem_recovery, print_fem, print_fit

    with single_threaded():
        result = bench_fit(cases=6 if args.quick else 40, progress=not args.json)
        fem = [] if args.quick else fem_recovery()
    if args.json:
        print(json.dumps({**result, "fem": fem}, indent=2))
    else:
        print_fit(result), print_fem(fem)


#: ``jassy bench`` choices, in the order of its help.
BENCHES: dict[str, Bench] = {
    "modal": Bench(_modal, "ModalBank vs plain numba and scipy, and the graph"),
    "float32": Bench(_float32, "float32 modal kernel and ModalBank vs a C float32 loop, 16-5000 modes"),
    "contact": Bench(_contact, "real-time factor of every built-in patch"),
    "live": Bench(_live, "underruns, latency and skew on a JACK dummy server"),
    "batch": Bench(_batch, "variants per minute serial vs 2 workers"),
    "burr": Bench(_burr, "haptic update time on a 256^3 phantom"),
    "rigid": Bench(_rigid, "world steps/s at 10-1000 bodies, wok real-time factor, ABA/Lemke/PGS"),
    "deform": Bench(
        _deform, "Green's function precompute and capacitance-matrix haptic update, cataract steps"
    ),
    "rod": Bench(_rod, "step time vs n (chained, mixed) and 1000 elements with 100 contacts"),
    "startup": Bench(_startup, "first render in a fresh process, empty and filled kernel cache (bell, wok)"),
    "anytime": Bench(_anytime, "error and CPU of mode budgets vs the full bank (bell, scrape, wok)"),
    "fit": Bench(_fit, "jassy fit's recall and errors on random synthetic recordings, and its speed"),
}


def run_bench(args: argparse.Namespace) -> int:
    """``jassy bench NAME``: run the bench of that name."""
    BENCHES[args.name].run(args)
    return 0


def bench_help() -> str:
    """The help of the ``name`` argument: one clause per bench."""
    return "; ".join(f"{name}: {bench.help}" for name, bench in BENCHES.items())
