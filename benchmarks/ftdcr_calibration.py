"""A real robot nobody here built: the ftdcr-v4 three-segment robot (data/ftdcr-v4) calibrated on
its train recording, its held-out validation recording predicted from the servo values alone.

The metric is the lab's: Euclidean tip RMSE after removing the mean offset between predicted and
measured tips. Beside it: the lab's own rigid-link model on the same files (9.38 mm fitted on this
recording, 12.11 mm with their paper's calibration), the mean predictor (78.0 mm) and the
data's equal-servo pairs (samples with equal servo values differ by 5.0 mm median, 6.2 mm RMS:
friction and hysteresis; a model without memory predicts one tip for both, so its error on them
is at least half that distance, about 3.1 mm RMS).

The fit is `tdct calibrate --dataset data/ftdcr-v4/dataset.toml --every 4` (its default values to
fit, tendon friction included, the geometry step from the data set's single-tendon pulls first).
With --start wrong it starts instead from a deliberately wrong description: each segment's tendon
pattern turned by 180 degrees plus a random +-30 degrees per tendon, no pretension, tendons 3
times as stiff, E doubled.

Beside the fit, the memoryless model (results/ftdcr_fitted_memoryless.toml: the same workflow on
the robot file without friction, results/ftdcr_calibration_memoryless.json) predicts the same
recordings: residuals along val.csv, the equal-servo pairs and the single-tendon pull-release
loops, with and without friction.

Run: python benchmarks/ftdcr_calibration.py [--every N] [--max-steps K] [--start lab|wrong]
Writes benchmarks/results/ftdcr_calibration.json (ftdcr_calibration_wrong.json with --start wrong),
ftdcr_prediction.png, ftdcr_pairs.png, ftdcr_residuals.png, ftdcr_hysteresis.png and
ftdcr_fitted.toml.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from _common import write_result

import tdct_jax as tdct
from tdct_jax import rig as rigs
from tdct_jax.calibrate_rig import equal_servo_pairs, pair_score, predict
from tdct_jax.plotting import plot_hysteresis, plot_pairs, plot_prediction, plot_residuals
from tdct_jax.recording import read_dataset
from tdct_jax.rig import Rig

HERE = Path(__file__).parent
MEMORYLESS = HERE / "results" / "ftdcr_fitted_memoryless.toml"
LOOPS = (0, 3, 6)
"""Tendons whose pull-release loop is drawn: the first of each segment."""
DATA = HERE.parent / "data" / "ftdcr-v4" / "dataset.toml"
BASELINES_MM = {
    "lab rigid-link model, fitted on this recording": 9.38,
    "lab rigid-link model, their paper's calibration": 12.11,
    "mean predictor": 78.0,
    "equal-servo pairs' tip distance (median; RMS 6.2)": 5.0,
    "memoryless bound: half the pairs' distance (RMS)": 3.1,
}


def wrong(lab: Rig, seed: int = 0) -> Rig:
    """The lab's rig from a deliberately wrong description (module docstring)."""
    rng = np.random.default_rng(seed)
    values = {
        f"tendons[{i}].angle": float(t.angle) + np.pi + np.radians(rng.uniform(-30, 30)) for i, t in enumerate(lab.robot.tendons)
    }
    values |= {f"tendons[{i}].stiffness": 3 * float(t.stiffness) for i, t in enumerate(lab.robot.tendons)}
    values |= {"pretension[*]": 0.0, "sections[*].E": 2 * float(lab.robot.sections[0].E)}
    return rigs.replace(lab, values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=4, help="fit every Nth training sample (default 4)")
    parser.add_argument("--max-steps", type=int, default=30, help="most Levenberg-Marquardt steps (default 30)")
    parser.add_argument("--start", choices=("lab", "wrong"), default="lab", help="the lab's values, or a wrong description")
    args = parser.parse_args()
    load_before = os.getloadavg()
    data = read_dataset(DATA)
    lab = Rig.from_toml(data.robot)
    print("predicting the validation file with the lab's own values (gravity off) ...")
    before = predict(lab, data.validation)
    print(f"  RMSE {1e3 * before.errors['rmse']:.2f} mm")
    train = data.train.subset(slice(None, None, args.every))
    start = lab if args.start == "lab" else wrong(lab)
    t = time.perf_counter()
    fit = tdct.calibrate(start, train, pulls=data.pulls, max_steps=args.max_steps, throw=False)  # the CLI's defaults
    fit_seconds = time.perf_counter() - t
    print(fit.summary())
    after = predict(fit.rig, data.validation)
    e = after.errors
    print(
        f"validation: RMSE {1e3 * e['rmse']:.2f} mm, mean {1e3 * e['mean']:.2f}, median {1e3 * e['median']:.2f}, "
        f"95th percentile {1e3 * e['p95']:.2f} mm; {1e3 * after.seconds_per_pose:.1f} ms per pose"
    )
    results = HERE / "results"
    suffix = "" if args.start == "lab" else "_wrong"
    if args.start == "lab":
        (results / "ftdcr_fitted.toml").write_text(fit.rig.to_toml())
    plot_prediction(
        after,
        fit,
        results / f"ftdcr_prediction{suffix}.png",
        title=f"ftdcr-v4: val.csv predicted from a fit on train.csv (1 sample in {args.every})",
        bound=3.1e-3,
    )
    print("the equal-servo pairs and the pull-release loops: each recording predicted in order ...")
    memoryless = Rig.from_toml(MEMORYLESS)
    models = {"with friction": fit.rig, "memoryless": memoryless}
    runs = {
        name: {k: predict(r, rec) for k, rec in (("train", data.train), ("val", data.validation), ("pulls", data.pulls))}
        for name, r in models.items()
    }
    runs["with friction"]["val"] = after
    pairs = equal_servo_pairs(data.train, data.validation)
    solved = np.all([np.concatenate([run["train"].codes, run["val"].codes]) == 0 for run in runs.values()], axis=0)
    pairs = pairs[solved[pairs].all(axis=1)]  # a sample that did not solve has no tip to compare
    measured = np.vstack([runs["memoryless"]["train"].measured, after.measured])
    tips = {name: np.vstack([run["train"].tips, run["val"].tips]) for name, run in runs.items()}
    scores = {name: pair_score(t, measured, pairs) for name, t in tips.items()}
    score = scores["with friction"]
    print(
        f"  share of the pairs' measured tip difference predicted: {score:.3f} ({len(pairs)} pairs; memoryless {scores['memoryless']:.3f})"
    )
    plot_pairs(
        tips["with friction"],
        measured,
        pairs,
        results / f"ftdcr_pairs{suffix}.png",
        title="ftdcr-v4: samples with equal servo values",
    )
    plot_residuals(
        after.measured,
        {name: np.where((run["val"].codes == 0)[:, None], run["val"].tips, np.nan) for name, run in runs.items()},
        results / f"ftdcr_residuals{suffix}.png",
        title="ftdcr-v4: val.csv predicted in order, with and without tendon friction",
    )
    pull_patterns = data.pulls.patterns()
    loops = []
    for i in LOOPS:
        rows = np.flatnonzero(
            (pull_patterns == pull_patterns[np.argmax(data.pulls.displacements[:, i])]) & (data.pulls.displacements[:, i] > -1e-3)
        )
        loops.append(
            dict(
                label=f"tendon {i + 1} (segment {i // 3 + 1}) pulled and released",
                servo=data.pulls.displacements[rows, i],
                measured=data.pulls.tip[rows],
                predicted={name: run["pulls"].tips[rows] for name, run in runs.items()},
            )
        )
    plot_hysteresis(
        loops,
        results / f"ftdcr_hysteresis{suffix}.png",
        title="ftdcr-v4: single-tendon pulls (tendon_pull.csv), predicted in order",
    )
    friction = {p: dict(value=fit.values[p], std_error=fit.std_errors[p]) for p in fit.params if p.endswith(".friction")}
    write_result(
        results / f"ftdcr_calibration{suffix}.json",
        pairs=dict(count=len(pairs), share_predicted=score, share_predicted_memoryless=scores["memoryless"], goal=0.5),
        friction=friction,
        memoryless=dict(
            validation=runs["memoryless"]["val"].to_dict(),
            train=runs["memoryless"]["train"].to_dict(),
            fitted=str(MEMORYLESS.name),
        ),
        train_prediction=runs["with friction"]["train"].to_dict(),
        start=args.start,
        load_average_before=load_before,
        load_average_after=os.getloadavg(),
        train_samples=len(train),
        every=args.every,
        fit_seconds=fit_seconds,
        fit=fit.to_dict(),
        validation_with_lab_values=before.to_dict(),
        validation=after.to_dict(),
        baselines_mm=BASELINES_MM,
        goal_mm=5.0,
    )


if __name__ == "__main__":
    np.set_printoptions(precision=4)
    main()
