"""Point-cloud completion with and without surface normals (the 3F2N+ paper's PF-Net experiment; issue 25).

    PYTHONPATH=src python3 benchmarks/completion.py --out /tmp/completion/completion.md \\
        --figure docs/figures/completion.png    # JSON sidecar: /tmp/completion/completion.json

The paper trains PF-Net on ShapeNet partial clouds with and without normals and reports F1 +3 %
and the Chamfer distance down by 0.40 mm (CD-l1) and 0.05 mm (CD-l2) with normals. ShapeNet is
not available offline, so this is a small version on the views of ``benchmarks/_objects.py``
(the ones of ``benchmarks/pose6d.py``: 8 asset meshes of ``synth`` resized to 12 cm, upright on
a table, distractor boxes, 64x64 px, the ``kinect_v1``, ``tof`` and ``realsense_d4xx`` noise):

- **Partial cloud**: 128 points drawn from the object mask's pixels with a noisy depth,
  back-projected, in the camera frame, centred on their centroid (so the network must infer
  the object's orientation from what it sees: the normals' job).
- **Ground truth**: the full mesh surface (area-uniform samples: 256 for the loss, 2048 for
  the scores) under the true pose, in the same frame.
- **Model** (PCN-like, one network for all objects, no object label): a PointNet encoder
  (per-point MLP 64-128-256, batch norm, max pool) and a fully connected decoder (256-256)
  to 256 points; Chamfer (L1, PCN's) loss, Adam, one-cycle learning rate.
- **Inputs**: ``xyz`` (3 per-point features); ``xyz+3f2n+`` and ``xyz+fals`` add the normals
  at the points (6): ``depthnormals.estimate_normals(depth, K, method="3f2n+")`` (the library's
  default) or OpenCV's ``cv2.rgbd.RgbdNormals`` FALS (window 5), both on the noisy depth image.
- **Scores** on the test views (other poses, lights and noise of the same objects), per view
  then averaged: F1 at tau = 5 mm and 10 mm (precision: predicted points within tau of the
  truth; recall: true points within tau of the prediction), CD-l1 = (mean nearest distance
  pred->true + true->pred) / 2 in mm, CD-l2 the same with squared distances in mm^2; mean +-
  sample std over ``--seeds`` seeds (initialisation and batch order), Welch's t-test against
  ``xyz``.

Defaults: 1600 training and 400 test views, 15 epochs, 3 seeds, one torch thread; about 9
minutes on the shared 2-core machine under load. Views are rendered once and cached in
``--cache`` (shared with pose6d.py). ``--clean``: the same views with the renderer's exact
depth (no sensor model), to tell the normals' value from the noise's cost
(docs/benchmarks.md sections 14 and 15).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import depthnormals as dn

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _objects as objs

INPUTS = ("xyz", "xyz+3f2n+", "xyz+fals")
BASELINE = "xyz"
N_IN = 128
N_OUT = 256
N_GT_TRAIN = 256
N_GT_EVAL = 2048
#: Metres to network units (decimetres).
UNIT = 10.0
TAUS_MM = (5.0, 10.0)


def clouds(
    views: dict,
    normals: dict[str, np.ndarray],
    names: tuple[str, ...],
    K: dn.Intrinsics,
    *,
    n_gt: int,
    seed: int,
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Partial inputs (N, F, 128) per input name, ground truth (N, n_gt, 3), both in network
    units around the partial centroid, and the views that have points (N,) bool."""
    idx, xyz, ok = objs.masked_points(views, K, N_IN, seed=seed)
    centroid = xyz.mean(2)
    part = (xyz - centroid[:, :, None]) * UNIT * ok[:, None, None]
    pts = np.stack([objs.surface_points(o, n_gt, seed=3) for o in objs.OBJECTS])
    R, t = views["R"].astype(np.float64), views["t"].astype(np.float64)
    gt = (pts[views["obj"]] @ R.transpose(0, 2, 1) + (t - centroid)[:, None]) * UNIT
    out = {}
    for name in names:
        src = objs.normal_source(name)
        out[name] = np.concatenate([part] + ([objs.gather(normals[src], idx)] if src else []), 1)
        out[name] = out[name].astype(np.float32)
    return out, gt.astype(np.float32), ok


def make_model(channels: int) -> Any:
    """PointNet encoder (64-128-256, max pool) and an FC decoder (256-256) to 256 points."""
    import torch
    from torch import nn

    class PCN(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            layers, c = [], channels
            for w in (64, 128, 256):
                layers += [nn.Conv1d(c, w, 1, bias=False), nn.BatchNorm1d(w), nn.ReLU()]
                c = w
            self.encoder = nn.Sequential(*layers)
            self.decoder = nn.Sequential(
                nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU(), nn.Linear(256, 3 * N_OUT)
            )

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return self.decoder(self.encoder(x).amax(2)).view(-1, N_OUT, 3)

    return PCN()


def nearest_sq(pred: Any, gt: Any) -> tuple[Any, Any]:
    """Squared distances (torch) from each predicted point to its nearest true one (B, P) and
    from each true point to its nearest prediction (B, G); the distance matrix by one matmul
    (``torch.cdist``'s backward was 5x slower here)."""
    import torch

    pp, gg = (pred * pred).sum(-1), (gt * gt).sum(-1)
    m = torch.baddbmm(gg[:, None, :], pred, gt.transpose(1, 2), alpha=-2.0)  # |g|^2 - 2 p.g
    a = (m.min(2).values + pp).clamp_min(0.0)
    b = ((m + pp[:, :, None]).min(1).values).clamp_min(0.0)
    return a, b


def chamfer_l1(pred: Any, gt: Any) -> Any:
    """Per-sample (mean nearest distance pred->gt + gt->pred) / 2 (torch)."""
    a, b = nearest_sq(pred, gt)
    return (a.clamp_min(1e-12).sqrt().mean(1) + b.clamp_min(1e-12).sqrt().mean(1)) / 2


def train_and_predict(
    x_tr: np.ndarray,
    gt_tr: np.ndarray,
    x_te: np.ndarray,
    *,
    seed: int,
    epochs: int,
    batch: int = 32,
    lr: float = 2e-3,
) -> np.ndarray:
    """Train on the training clouds; return the (N, 256, 3) test predictions (network units)."""
    import torch

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    model = make_model(x_tr.shape[1])
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n = x_tr.shape[0]
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=epochs * -(-n // batch))
    xt, gt = torch.from_numpy(x_tr), torch.from_numpy(gt_tr)
    model.train()
    for _ in range(epochs):
        order = torch.randperm(n, generator=gen)
        for i in range(0, n, batch):
            j = order[i : i + batch]
            loss = chamfer_l1(model(xt[j]), gt[j]).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
    model.eval()
    out = []
    with torch.no_grad():
        for i in range(0, x_te.shape[0], 100):
            out.append(model(torch.from_numpy(x_te[i : i + 100])).numpy())
    return np.concatenate(out)


def completion_scores(pred: np.ndarray, gt: np.ndarray, ok: np.ndarray) -> dict[str, float]:
    """F1 at each tau, CD-l1 (mm) and CD-l2 (mm^2) per view, averaged over the views with points."""
    import torch

    f1 = {tau: [] for tau in TAUS_MM}
    l1, l2 = [], []
    for i in range(0, pred.shape[0], 50):
        with torch.no_grad():
            a2, b2 = nearest_sq(
                torch.from_numpy(pred[i : i + 50]).double(), torch.from_numpy(gt[i : i + 50]).double()
            )
        a, b = np.sqrt(a2.numpy()) * (1000.0 / UNIT), np.sqrt(b2.numpy()) * (1000.0 / UNIT)  # mm
        l1.append((a.mean(1) + b.mean(1)) / 2)
        l2.append(((a**2).mean(1) + (b**2).mean(1)) / 2)
        for tau in TAUS_MM:
            p, r = (a < tau).mean(1), (b < tau).mean(1)
            f1[tau].append(np.where(p + r > 0, 2 * p * r / np.maximum(p + r, 1e-12), 0.0))
    sel = ok
    out = {f"f1_{tau:g}mm": float(np.concatenate(v)[sel].mean()) for tau, v in f1.items()}
    out["cd_l1_mm"] = float(np.concatenate(l1)[sel].mean())
    out["cd_l2_mm2"] = float(np.concatenate(l2)[sel].mean())
    return out


METRICS = (
    ("f1_10mm", "F1@10mm %", 100.0),
    ("f1_5mm", "F1@5mm %", 100.0),
    ("cd_l1_mm", "CD-l1 mm", 1.0),
    ("cd_l2_mm2", "CD-l2 mm^2", 1.0),
)


def summarise(results: dict[str, list[dict]], errors: dict[str, float]) -> tuple[str, dict]:
    """Markdown table (mean +- std over seeds) and Welch p-values against ``xyz``."""
    lines = [
        "| input | "
        + " | ".join(f"{h} (mean +- std)" for _, h, _ in METRICS)
        + " | CD-l1 per seed | p (CD-l1) vs xyz | p (F1@10mm) vs xyz | normal err on object (deg) |",
        "|---|" + "---:|" * len(METRICS) + "---|---:|---:|---:|",
    ]
    pvals: dict[str, dict[str, float]] = {}
    ref = (
        {k: np.array([r[k] for r in results[BASELINE]]) for k in ("cd_l1_mm", "f1_10mm")}
        if BASELINE in results
        else None
    )
    for name, runs in results.items():
        cells = []
        for key, _, scale in METRICS:
            a = np.array([r[key] for r in runs]) * scale
            cells.append(f"{a.mean():.2f} +- {objs.sd(a):.2f}")
        cd = np.array([r["cd_l1_mm"] for r in runs])
        f1 = np.array([r["f1_10mm"] for r in runs])
        if ref is not None and name != BASELINE:
            pvals[name] = {
                "cd_l1": objs.welch_p(cd, ref["cd_l1_mm"]),
                "f1_10mm": objs.welch_p(f1, ref["f1_10mm"]),
            }
        pc, pf = (pvals[name]["cd_l1"], pvals[name]["f1_10mm"]) if name in pvals else (float("nan"),) * 2
        src = objs.normal_source(name)
        err = f"{errors[src]:.1f}" if src in errors else "-"
        lines.append(
            f"| {name} | " + " | ".join(cells) + f" | {' / '.join(f'{v:.2f}' for v in cd)} | "
            f"{'-' if np.isnan(pc) else f'{pc:.3f}'} | {'-' if np.isnan(pf) else f'{pf:.3f}'} | {err} |"
        )
    return "\n".join(lines), pvals


def figure(
    path: Path,
    inputs: dict[str, np.ndarray],
    gt: np.ndarray,
    preds: dict[str, np.ndarray],
    picks: list[int],
    labels: list[str],
) -> None:
    """Rows: test views; columns: partial + truth, each input's prediction (seed 0); top views
    (x right, z away from the camera), so the completed back side shows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = ["partial (black) + truth (grey)", *preds]
    fig, axes = plt.subplots(
        len(picks), len(cols), figsize=(2.2 * len(cols), 2.2 * len(picks) + 0.3), squeeze=False
    )
    s = 1000.0 / UNIT
    for r, i in enumerate(picks):
        part = next(iter(inputs.values()))[i, :3].T * s
        g = gt[i] * s
        for c in range(len(cols)):
            ax = axes[r, c]
            ax.scatter(g[:, 0], g[:, 2], s=0.3, c="0.75")
            if c == 0:
                ax.scatter(part[:, 0], part[:, 2], s=0.6, c="k")
            else:
                p = preds[cols[c]][i] * s
                ax.scatter(p[:, 0], p[:, 2], s=0.6, c="tab:red")
            ax.set_aspect("equal")
            ax.set_xlim(-110, 110)
            ax.set_ylim(-60, 160)
            ax.tick_params(labelsize=5)
            if r == 0:
                ax.set_title(cols[c], fontsize=7)
            if c == 0:
                ax.set_ylabel(f"{labels[r]}\nz (mm)", fontsize=6)
    fig.suptitle(
        "top views (x, z in mm; camera at the bottom); red: predicted completion (seed 0)", fontsize=8
    )
    objs.save_figure(fig, path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--train", type=int, default=1600, help="training views (default 1600)")
    p.add_argument("--test", type=int, default=400, help="test views (default 400)")
    p.add_argument("--size", type=int, default=64, help="image side, px (default 64)")
    p.add_argument("--epochs", type=int, default=15)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--inputs", default=",".join(INPUTS))
    p.add_argument("--clean", action="store_true", help="exact rendered depth, no sensor noise")
    p.add_argument("--threads", type=int, default=1, help="torch and library threads (default 1)")
    p.add_argument(
        "--cache",
        type=Path,
        default=Path("/tmp/depthnormals-bench"),
        help="folder of the rendered views (shared with pose6d.py)",
    )
    p.add_argument("--out", type=Path, help="markdown table (and a .json sidecar beside it)")
    p.add_argument("--figure", type=Path, help="PNG of a few test completions")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)
    dn.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    names = tuple(args.inputs.split(","))
    bad = [n for n in names if n not in INPUTS]
    if bad:
        p.error(f"unknown input(s) {bad}; valid: {', '.join(INPUTS)}")
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", flush=True)

    log(f"views: {args.train} train + {args.test} test, {args.size}x{args.size}, {len(objs.OBJECTS)} objects")
    tr, te, K, n_tr, n_te, errors = objs.views_and_normals(args, names, log)
    x_tr, gt_tr, ok_tr = clouds(tr, n_tr, names, K, n_gt=N_GT_TRAIN, seed=0)
    x_te, gt_te, ok_te = clouds(te, n_te, names, K, n_gt=N_GT_EVAL, seed=1)
    x_tr, gt_tr = {k: v[ok_tr] for k, v in x_tr.items()}, gt_tr[ok_tr]
    log(f"clouds: {int(ok_tr.sum())} train, {int(ok_te.sum())} test views with object points")
    results: dict[str, list[dict]] = {}
    preds: dict[str, np.ndarray] = {}
    for name in names:
        results[name] = []
        for seed in range(args.seeds):
            t = time.perf_counter()
            pred = train_and_predict(x_tr[name], gt_tr, x_te[name], seed=seed, epochs=args.epochs)
            s = completion_scores(pred, gt_te, ok_te)
            s.update(seed=seed, channels=int(x_tr[name].shape[1]), seconds=round(time.perf_counter() - t, 1))
            results[name].append(s)
            if seed == 0:
                preds[name] = pred
            log(
                f"{name:<10} seed {seed}: F1@10mm {100 * s['f1_10mm']:.1f} % "
                f"F1@5mm {100 * s['f1_5mm']:.1f} % "
                f"CD-l1 {s['cd_l1_mm']:.2f} mm CD-l2 {s['cd_l2_mm2']:.1f} mm^2 ({s['seconds']:.0f} s)"
            )
    table, pvals = summarise(results, errors)
    wall = time.perf_counter() - t0
    print(table)
    print(f"wall time {wall:.0f} s")
    if args.out:
        objs.write_report(args.out, table, args, K, wall=wall, errors=errors, points_in=N_IN,
                          points_out=N_OUT, gt_points_eval=N_GT_EVAL, taus_mm=list(TAUS_MM),
                          p_vs_xyz=pvals, results=results)
    if args.figure and preds:
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        picks = [int(np.flatnonzero((te["obj"] == o) & ok_te)[0]) for o in range(min(4, len(objs.OBJECTS)))]
        figure(args.figure, x_te, gt_te, preds, picks, [objs.OBJECTS[te["obj"][i]] for i in picks])
        log(f"figure written to {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
