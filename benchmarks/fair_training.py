"""One fair retraining of every learned method (issue 27 item 4): the same recipe, budget and selection rule.

Every run is ``tespike train`` on the data engine with the same recipe (mu-L1 loss,
learning rate, halving, batch, crop, pool, the same share of noisy clips) and the
same selection rule (validation on the held-out set every ``--validate-every``
steps, the best checkpoint kept). The runs of one group start together on one
machine and get the same wall-clock budget (``--minutes``), so each had the same
share of the same cores and accelerator; the summary gives the steps each reached,
which is where the methods' speeds show.

Groups (``--groups``):

- ``fair``: every learned method from its initial weights on every camera it ships
  for: net on te / ml-msb / ml, Spk2ImgNet, BSF and MambaSpike on te / ml-msb, and
  the one-branch MambaSpike on ml-msb (the paper's spade row);
- ``continue``: the shipped network weights warm-started (``--init``) and trained on
  the same engine with noise, at a lower learning rate (the network's shipped weights
  keep their longer training; the ``fair`` net rows are the budget-matched ones);
- ``continue-baselines``: the same for every shipped baseline file (the msb MambaSpike,
  now of several parsings, and the one-branch MambaSpike both start from the shipped
  one-branch ``mambaspike-ml-msb.pt``: ``--init`` copies the tensors that match);
- ``ablation``: the paper's Table 3 cases 1..6 of the network on te, from scratch.

Each run writes ``DIR/<name>.pt`` and ``DIR/<name>.run/`` (log.csv, curves.png);
``DIR/summary.md`` and ``DIR/summary.json`` list each run's command, steps, wall
seconds and best validation PSNR-mu. Progress (each run's step) is printed every
``--report`` seconds.

    python3 benchmarks/fair_training.py --out runs --minutes 7 --device cuda --groups fair continue
    python3 benchmarks/fair_training.py --resume runs --minutes 11     # every run continued to 11 min in all
    python3 benchmarks/fair_training.py --plot runs --png curves.png     # validation against run time
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tespike.recon.learned import WEIGHTS_DIR, weights_name  # noqa: E402

#: The one recipe of every run (``tespike train`` flags).
RECIPE = ("--loss", "mu-l1", "--halve-every", "20", "--threads", "1", "--workers", "1", "--pool", "32",
          "--refresh", "12", "--noise-fraction", "0.5", "--seed", "0")
FAIR = [("net", "te"), ("net", "ml-msb"), ("net", "ml"),
        ("spk2imgnet", "te"), ("spk2imgnet", "ml-msb"), ("bsf", "te"), ("bsf", "ml-msb"),
        ("mambaspike", "te"), ("mambaspike", "ml-msb"), ("mambaspike1", "ml-msb")]


def jobs(groups: list[str], lr: float, continue_lr: float) -> list[tuple[str, list[str]]]:
    """(run name, ``tespike train`` arguments without --out/--minutes/--device) of each group."""
    out = []
    if "fair" in groups:
        out += [(f"fair-{m}-{c}", ["--config", c, "--method", m, "--lr", str(lr)]) for m, c in FAIR]
    if "continue" in groups:
        shipped = WEIGHTS_DIR
        out += [(f"continue-net-{c}", ["--config", c, "--method", "net", "--lr", str(continue_lr),
                                       "--init", str(shipped / weights_name("net", c))])
                for c in ("te", "ml-msb", "ml")]
    if "continue-baselines" in groups:
        shipped = WEIGHTS_DIR
        # mambaspike (msb: 3 parsings) and mambaspike1 both start from the shipped one-branch file
        source = {("mambaspike1", "ml-msb"): ("mambaspike", "ml-msb")}
        out += [(f"continue-{m}-{c}", ["--config", c, "--method", m, "--lr", str(continue_lr),
                                       "--init", str(shipped / weights_name(*source.get((m, c), (m, c))))])
                for m, c in FAIR if m != "net"]
    if "ablation" in groups:
        out += [(f"ablation-{case}", ["--config", "te", "--ablation", str(case), "--lr", str(lr)])
                for case in range(1, 7)]
    return out


def last_step(run: Path) -> int:
    log = run / "log.csv"
    if not log.is_file():
        return 0
    with open(log, "rb") as handle:
        handle.seek(max(0, log.stat().st_size - 200))
        tail = handle.read().decode(errors="replace").strip().splitlines()
    try:
        return int(tail[-1].split(",")[0])
    except (IndexError, ValueError):
        return 0


def summary_row(name: str, out: Path, command: str, rc: int) -> dict:
    row = {"run": name, "command": command, "exit": rc}
    weights = out / f"{name}.pt"
    if rc == 0 and weights.is_file():
        from tespike.recon.learning.weights import read_weights
        meta = read_weights(weights, "weights")["meta"]
        row.update(steps=meta["steps"], wall_seconds=meta["wall_seconds"], parameters=meta["parameters"],
                   validation=meta.get("validation"))
    row["steps_run"] = last_step(out / f"{name}.run")
    return row


def validation_curve(run: Path) -> tuple[list[float], list[float]]:
    """(wall seconds, mean validation PSNR-mu) of each validation of a run folder."""
    with open(run / "validation.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    return [float(r["seconds"]) for r in rows], [float(r["mean"]) for r in rows]


def plot(folder: Path, png: str) -> None:
    """Validation PSNR-mu against each run's wall time, one panel per camera and one for the ablation."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tespike.recon.pictures import save_figure
    panels = {"TE": lambda n: n.endswith("-te") and not n.startswith("ablation"),
              "ML msb": lambda n: n.endswith("-ml-msb"), "ML count": lambda n: n.endswith("-ml"),
              "Table 3 ablation (TE)": lambda n: n.startswith("ablation")}
    runs = sorted(p for p in folder.glob("*.run") if (p / "validation.csv").is_file())
    if not runs:
        raise SystemExit(f"fair_training: no run folder with a validation.csv in {str(folder)!r}")
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 4.2), sharey=False)
    for ax, (title, wanted) in zip(axes, panels.items()):
        for run in runs:
            name = run.name[:-len(".run")]
            if wanted(name):
                seconds, mean = validation_curve(run)
                ax.plot(seconds, mean, "--" if name.startswith("continue") else "-", marker="o", ms=3,
                        label=name)
        ax.set_title(title)
        ax.set_xlabel("wall seconds of the run")
        ax.set_ylabel("validation PSNR-mu (dB, mean of 6 held-out cases)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, png)
    print(f"wrote {png}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plot", metavar="DIR", help="plot the validation curves of a runs folder (no training)")
    parser.add_argument("--png", default="fair_training.png", help="the plot --plot writes")
    parser.add_argument("--out", help="folder of the runs (must not exist)")
    parser.add_argument("--resume", metavar="DIR", help="continue every run of a finished runs folder to --minutes "
                        "in all (each its recorded command with --resume)")
    parser.add_argument("--minutes", type=float, help="wall budget of every run")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--groups", nargs="+", default=["fair"], choices=["fair", "continue", "continue-baselines", "ablation"])
    parser.add_argument("--lr", type=float, default=5e-4, help="learning rate of runs from scratch")
    parser.add_argument("--continue-lr", type=float, default=2e-4, help="learning rate of the continued runs")
    parser.add_argument("--validate-every", type=int, default=250)
    parser.add_argument("--steps", type=int, default=None, help="step budget too (the first reached ends a run)")
    parser.add_argument("--pool", type=int, default=None, help="clips a step draws from (default: the recipe's)")
    parser.add_argument("--noisy-input", choices=("mean", "law"), default=None,
                        help="what noisy clips' methods see (tespike train --noisy-input; default: the recipe's mean)")
    parser.add_argument("--engine-workers", type=int, default=None, metavar="N",
                        help="engine processes of every run (default: the recipe's 1; a few runs on many cores)")
    parser.add_argument("--only", nargs="*", default=None, help="run only these run names")
    parser.add_argument("--report", type=float, default=30.0, help="seconds between progress lines")
    args = parser.parse_args(argv)
    if args.plot is not None:
        plot(Path(args.plot), args.png)
        return 0
    if args.resume is not None:
        if args.minutes is None:
            parser.error("--resume DIR needs --minutes (the budget of each run, in all)")
        commands = resumed(Path(args.resume), args.minutes, args.only)
        return run_all(Path(args.resume), commands, args.minutes, args.device, args.report)
    if args.out is None or args.minutes is None:
        parser.error("--out and --minutes are needed to train (or --plot DIR)")
    out = Path(args.out)
    if out.exists():
        print(f"fair_training: --out {str(out)!r} exists (a runs folder is one run's)", file=sys.stderr)
        return 2
    out.mkdir(parents=True)
    todo = [(n, a) for n, a in jobs(args.groups, args.lr, args.continue_lr) if args.only is None or n in args.only]
    commands = {}
    for name, extra in todo:
        cmd = [sys.executable, "-m", "tespike", "train", *extra, *RECIPE, "--minutes", str(args.minutes),
               "--device", args.device, "--validate-every", str(args.validate_every), "--progress", "off",
               "--out", str(out / f"{name}.pt")]
        if args.pool is not None:
            cmd += ["--pool", str(args.pool)]
        if args.noisy_input is not None:
            cmd += ["--noisy-input", args.noisy_input]
        if args.engine_workers is not None:
            cmd += ["--workers", str(args.engine_workers)]
        if args.steps is not None:
            cmd += ["--steps", str(args.steps)]
        commands[name] = cmd
    return run_all(out, commands, args.minutes, args.device, args.report)


def resumed(out: Path, minutes: float, only) -> dict[str, list[str]]:
    """Each run of a runs folder's ``summary.json`` continued (``--resume``) to ``minutes`` in all:
    its recorded command, without ``--init`` (the warm start is in its checkpoint)."""
    summary = out / "summary.json"
    if not summary.is_file():
        raise SystemExit(f"fair_training: --resume {str(out)!r}: no summary.json (not a finished runs folder)")
    commands = {}
    for row in json.loads(summary.read_text()):
        if only is not None and row["run"] not in only:
            continue
        args = shlex.split(row["command"])[1:]          # drop the leading "tespike"
        if "--init" in args:
            at = args.index("--init")
            del args[at:at + 2]
        args[args.index("--minutes") + 1] = str(minutes)
        commands[row["run"]] = [sys.executable, "-m", "tespike", *args, "--resume"]
    return commands


def run_all(out: Path, commands: dict[str, list[str]], minutes: float, device: str, report: float) -> int:
    """Start every run together, print their steps every ``report`` seconds, write the summary."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    procs = {}
    for name, cmd in commands.items():
        log = open(out / f"{name}.log", "a")
        procs[name] = (subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT), cmd, log)
    print(f"{len(procs)} runs started, {minutes} min each, device {device}", flush=True)
    start = time.monotonic()
    while any(p.poll() is None for p, _, _ in procs.values()):
        time.sleep(min(report, 5.0))
        if int(time.monotonic() - start) % int(report) < 5:
            steps = " ".join(f"{n}:{last_step(out / f'{n}.run')}" for n in procs)
            print(f"[{time.monotonic() - start:5.0f} s] {steps}", flush=True)
    rows = []
    for name, (proc, cmd, log) in procs.items():
        log.close()
        shown = "tespike " + " ".join(shlex.quote(a) for a in cmd[3:])
        rows.append(summary_row(name, out, shown, proc.returncode))
    (out / "summary.json").write_text(json.dumps(rows, indent=1))
    with open(out / "summary.md", "w") as handle:
        handle.write("| run | exit | steps | wall s | parameters | best validation PSNR-mu (mean) |\n")
        handle.write("| --- | ---: | ---: | ---: | ---: | ---: |\n")
        for r in rows:
            mean = (r.get("validation") or {}).get("mean")
            handle.write(f"| {r['run']} | {r['exit']} | {r['steps_run']} | {r.get('wall_seconds', '-')} | "
                         f"{r.get('parameters', '-')} | {'-' if mean is None else f'{mean:.2f}'} |\n")
    print((out / "summary.md").read_text(), flush=True)
    for r in rows:
        if r["exit"] != 0:
            tail = (out / f"{r['run']}.log").read_text().strip().splitlines()[-3:]
            print(f"{r['run']} failed (exit {r['exit']}): " + " | ".join(tail), flush=True)
    return 0 if all(r["exit"] == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
