"""Command line: ``pdem run SCENE.yaml``, ``pdem study FILE.yaml``, ``pdem info FILE.h5``,
``pdem plot FILE.h5``, ``pdem export FILE.h5``: a shell over the Python API (pdem.api).

With the Python API's defaults, the only place that names ``MPI.COMM_WORLD``; everything else
receives the communicator.
"""

from __future__ import annotations

import argparse
import os
import sys


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pdem", description="Parallel distinct element method "
                                "for 3D polyhedral blocks. Run under mpiexec for parallel runs.")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a scene file")
    r.add_argument("scene", help="scene file (YAML); see docs/scene-file.md")
    r.add_argument("--output", "-o", help="override output.file")
    end = r.add_mutually_exclusive_group()
    end.add_argument("--time", type=float, help="model time to run instead of solve.*")
    end.add_argument("--steps", type=int, help="steps to run instead of solve.*")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    rs = sub.add_parser("restart", help="continue a run from a checkpoint (any rank count)")
    rs.add_argument("checkpoint", help="checkpoint file written by a run with `checkpoint:`")
    rs.add_argument("--output", "-o", help="output file (default: the scene's, suffixed "
                    "with -from<step>)")
    end = rs.add_mutually_exclusive_group()
    end.add_argument("--time", type=float, help="model time to run from the checkpoint")
    end.add_argument("--steps", type=int, help="steps to run from the checkpoint")
    rs.add_argument("--quiet", "-q", action="store_true", help="no progress lines")
    w = sub.add_parser("warmup", help="compile and cache the kernels some scenes use, so that "
                       "their runs start in seconds (under mpiexec: also the parallel ones)")
    w.add_argument("scenes", nargs="*", metavar="SCENE", help="scene files (default: a built-in "
                   "two-block scene)")
    w.add_argument("--steps", type=int, default=20, help="steps to run each scene (default 20)")
    w.add_argument("--once", action="store_true", help="nothing to do if this cache was warmed "
                   "with these scenes on this many ranks already")
    st = sub.add_parser("study", help="run the studies of a scene file (studies:) or a study "
                        "file: cases over sampled or gridded parameters, side by side under "
                        "mpiexec, resumed where a killed study stopped (docs/studies.md)")
    st.add_argument("file", help="scene file with studies:, or a study file (scene: ...)")
    st.add_argument("--only", metavar="NAME", help="run only the study called NAME")
    pl = sub.add_parser("plot", help="plot a run's energy budget, histories or factor-of-safety "
                        "search, or a study's outputs and probability of failure, as PNG "
                        "(needs matplotlib)")
    pl.add_argument("file", help="output file of a run, or a study file (HDF5)")
    pl.add_argument("--what", help="energy, history, fos or study (default: study for a study "
                    "file, fos for a run with a factor-of-safety search, else energy)")
    pl.add_argument("--history", metavar="NAME", help="the history to plot (--what history; "
                    "default: every block and station history)")
    pl.add_argument("--out", "-o", metavar="PNG", help="image file (default: FILE's stem with "
                    "-WHAT.png)")
    c = sub.add_parser("check", help="validate a scene file and report its blocks")
    c.add_argument("scene")
    i = sub.add_parser("info", help="summarise a pdem output file")
    i.add_argument("file")
    e = sub.add_parser("export", help="write the block surfaces of an output file as one mesh "
                       "file per snapshot (VTU, VTK, ...), for tools that do not read XDMF")
    e.add_argument("file", help="output file of a run (HDF5)")
    # not argparse choices: an unknown format gets the one-line error (status 1) of other errors
    e.add_argument("--format", "-f", default="vtu",
                   help="vtu (default), vtk, xdmf, gmsh, med or hmf")
    e.add_argument("--out", "-o", metavar="DIR_OR_STEM", help="directory, or path stem of the "
                   "files (default: beside FILE, with its stem)")
    e.add_argument("--every", type=int, default=1, metavar="K",
                   help="export every K-th snapshot (default 1: all)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "info":
        return _info(args)
    if args.command == "export":
        return _export(args)
    if args.command == "plot":
        return _plot(args)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    from mpi4py import MPI

    from .errors import UserError
    from .mpi import install_abort_hook, setup_logging

    comm = MPI.COMM_WORLD
    log = setup_logging(comm)
    install_abort_hook(comm)
    try:
        if args.command == "check":
            return _check(args, comm, log)
        if args.command == "restart":
            return _restart(args, comm, log)
        if args.command == "study":
            from .study.runner import run_study

            run_study(args.file, comm, only=args.only)
            return 0
        if args.command == "warmup":
            from .warmup import main as warmup

            return warmup(comm, args.scenes, args.steps, args.once, log)
        return _run(args, comm, log)
    except UserError as exc:
        # every rank validates the same input, so every rank reaches here: no hang
        if comm.rank == 0:
            print(f"pdem: {exc}", file=sys.stderr)
        return 1


def _with_output(scene, path):
    return scene.model_copy(update={"output": scene.output.model_copy(update={"file": path})})


def _march(args, comm, log, scene, state=None) -> int:
    """Build the simulation (on every rank alike), run it, close the files (pdem.api)."""
    import logging

    from .api import simulate
    from .signals import install

    if args.quiet:
        log.setLevel(logging.WARNING)
    # SIGTERM, SIGINT or SIGUSR1 (a batch system's warning) only set a flag from here on: the
    # run stops at a step boundary every rank agrees on, with a checkpoint
    stop = install()
    summary, sim = simulate(scene, comm, checkpoint=state, stop=stop, time=args.time,
                            steps=args.steps)
    stem = os.path.splitext(scene.output.file)[0]
    zoned = f", {stem}-zones.xdmf" if sim.state.grids is not None else ""  # zoned blocks
    log.info("wrote %s (+ %s.xdmf, %s-centroids.xdmf%s)", scene.output.file, stem, stem, zoned)
    if summary["stopped"]:
        return _stopped(comm, summary, sim)
    return 0


def _stopped(comm, summary, sim) -> int:
    """The message of a run stopped by a signal; its exit status is the shell's 128 + signal."""
    from .signals import name

    signum = summary["stopped"]
    if comm.rank == 0:
        print(f"pdem: stopped by {name(signum)} at step {sim.step} (t = {sim.time:.6g} s); "
              f"continue with: pdem restart {summary['checkpoint']}", file=sys.stderr, flush=True)
    return 128 + signum


def _run(args, comm, log) -> int:
    from .config import load_scene

    scene = load_scene(args.scene)
    return _march(args, comm, log, _with_output(scene, args.output) if args.output else scene)


def _restart(args, comm, log) -> int:
    from .config import parse_scene
    from .errors import UserError
    from .io.checkpoint import open_checkpoint

    try:  # the attributes here; each rank reads its rows at the restore (collective)
        ck = open_checkpoint(args.checkpoint)
    except (OSError, ValueError, KeyError) as exc:
        raise UserError(f"cannot restart from {args.checkpoint}: {exc}") from None
    scene = parse_scene(ck["attrs"]["scene"], f"{args.checkpoint}:scene")
    step = int(ck["attrs"]["step"])
    out = args.output or f"{os.path.splitext(scene.output.file)[0]}-from{step}.h5"
    return _march(args, comm, log, _with_output(scene, out), state=ck)


def _check(args, comm, log) -> int:
    from .config import load_scene
    from .simulation import Simulation

    scene = load_scene(args.scene)
    sim = Simulation(scene, comm, output=False, release=False)  # the report reads it all
    log.info("%s: valid; %d blocks, %d initial contacts, dt=%.4g s, ctol=%.4g m",
             args.scene, sim.blocks.n, sim.contacts.n, sim.dt, sim.state.ctol)
    log.info("pre-flight estimate: %s", sim.state.estimate)
    from .model.report import rock_mass_report

    for line in rock_mass_report(scene, sim.specs, sim.state.glob):
        log.info("%s", line)
    return 0


def _info(args) -> int:
    from .io.info import summarise

    try:
        print(summarise(args.file))
    except (OSError, ValueError, KeyError) as exc:
        print(f"pdem info: {args.file}: {exc}", file=sys.stderr)
        return 1
    return 0


def _plot(args) -> int:
    from .errors import UserError
    from .plot import plot

    try:
        out = plot(args.file, what=args.what, history=args.history, out=args.out)
    except (UserError, OSError, ValueError, KeyError) as exc:
        print(f"pdem plot: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out}")
    return 0


def _export(args) -> int:
    from .errors import UserError
    from .io.export import export

    try:
        files = export(args.file, args.format, out=args.out, every=args.every)
    except (UserError, OSError, ValueError, KeyError) as exc:
        # OSError etc.: a damaged or odd HDF5 file; still one line, as for `pdem info`
        print(f"pdem export: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {len(files)} files: {files[0]} .. {files[-1]}" if len(files) > 1
          else f"wrote {files[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
