"""6D object pose with and without surface normals (the 3F2N+ paper's LineMOD experiment; issue 25).

    PYTHONPATH=src python3 benchmarks/pose6d.py --out /tmp/pose6d/pose6d.md \\
        --figure docs/figures/pose6d.png        # JSON sidecar: /tmp/pose6d/pose6d.json

The paper trains PoseNet and a GCN on LineMOD with RGB+Depth or RGB+Normal input and reports
RGB+Normal ahead (ADD accuracy +1.1 % and +1.6 %). LineMOD is not available offline, so this is
a small LineMOD-like version (``benchmarks/_objects.py``): 8 asset meshes of ``synth`` (the
pybullet set, resized to 12 cm) upright on a table at random yaw, two distractor boxes, camera
0.6-1.0 m away at 25-65 deg elevation, 64x64 px, a colour image (per-face albedo, Lambertian
shading, random light, pixel noise), depth through the ``kinect_v1``, ``tof`` and
``realsense_d4xx`` sensor models in turn, and the object mask given (as a segmentation).
Training views and test views are different poses, lights and noise of the same objects (as
LineMOD's splits are).

Two estimators, each trained on every input from ``--seeds`` seeds (initialisation and batch
order; the data are the same for every seed), one network for all objects (object one-hot
given):

- ``image`` (in the spirit of PoseNet): a 4-level strided CNN (16-32-64-128 channels, batch
  norm) on the 64x64 image, flattened, one-hot, a hidden layer, 9 outputs (rotation as two
  columns, Gram-Schmidt; translation). Inputs: ``rgb+depth`` (colour, depth - 0.8 m, mask:
  5 channels), ``rgb+3f2n+`` and ``rgb+fals`` (colour, normals, mask: 7; no depth, as in the
  paper's RGB+Normal), ``rgb+depth+3f2n+`` (8), and on request ``rgb`` (colour, mask: the
  floor without geometry).
- ``points`` (PointNet): 128 points back-projected from the masked noisy depth, centred on
  their centroid, per-point MLP 64-128-128 with batch norm, max pool, one-hot, a hidden
  layer, 9 outputs (translation relative to the centroid). Per-point features: ``xyz+rgb``;
  ``xyz+rgb+3f2n+`` and ``xyz+rgb+fals`` add the normals (a point network needs positions).

Normals: ``3f2n+`` = ``depthnormals.estimate_normals(depth, K, method="3f2n+")`` (the library's
default); ``fals`` = OpenCV's ``cv2.rgbd.RgbdNormals`` FALS (window 5). Loss: ADD (mean
distance of 128 model points under the predicted and the true pose), Adam, one-cycle
learning rate. Scores on the test views: ADD accuracy (ADD < 10 % of the object diameter, as
on LineMOD), mean ADD (mm), rotation error (deg) and translation error (mm); mean +- sample
std over seeds, and Welch's t-test of each input against the depth input.

Defaults: 1600 training and 400 test views, 20 epochs (image and points), 3 seeds, one
torch thread; about 12 minutes on the shared 2-core machine under load. Views are rendered
once and cached in ``--cache`` (atomic ``.npz``). ``--clean``: the same views with the
renderer's exact depth (no sensor model), to tell the normals' value from the noise's cost
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

IMAGE_INPUTS = ("rgb+depth", "rgb+3f2n+", "rgb+fals", "rgb+depth+3f2n+", "rgb")
#: The inputs run by default (``rgb``, the floor without geometry, on request).
DEFAULT_IMAGE = IMAGE_INPUTS[:4]
POINT_INPUTS = ("xyz+rgb", "xyz+rgb+3f2n+", "xyz+rgb+fals")
#: The reference input of each model (the significance tests are against it).
BASELINE = {"image": "rgb+depth", "points": "xyz+rgb"}
N_POINTS = 128
LOSS_POINTS = 128
DEPTH_CENTRE = 0.8


# ---------------------------------------------------------------- inputs


def image_inputs(
    views: dict, normals: dict[str, np.ndarray], names: tuple[str, ...]
) -> dict[str, np.ndarray]:
    """(N, C, S, S) float32 per image input."""
    mask = views["mask"][:, None].astype(np.float32)
    d = views["depth"][:, None]
    depth = np.where(d > 0, d - DEPTH_CENTRE, 0.0).astype(np.float32)
    out = {}
    for name in names:
        src = objs.normal_source(name)
        geo = ([depth] if name.startswith("rgb+depth") else []) + ([normals[src]] if src else [])
        out[name] = np.concatenate([views["rgb"], *geo, mask], axis=1)
    return out


def point_inputs(
    views: dict, normals: dict[str, np.ndarray], names: tuple[str, ...], K: dn.Intrinsics, *, seed: int = 0
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """(N, F, 128) float32 per point input (xyz centred, decimetres) and the (N, 3) centroids (m).

    Points: pixels of the mask with a depth, 128 drawn (with replacement when fewer), the same
    draw for every input; a view with no such pixel gets 128 zeros at the origin.
    """
    idx, xyz, ok = objs.masked_points(views, K, N_POINTS, seed=seed)
    centroid = np.where(ok[:, None], xyz.mean(2), 0.0)
    xyz = (xyz - centroid[:, :, None]) * 10.0 * ok[:, None, None]
    rgb = objs.gather(views["rgb"], idx)
    out = {}
    for name in names:
        src = objs.normal_source(name)
        parts = [xyz, rgb] + ([objs.gather(normals[src], idx)] if src else [])
        out[name] = np.concatenate(parts, 1).astype(np.float32)
    return out, centroid.astype(np.float32)


# ---------------------------------------------------------------- models


def make_model(kind: str, channels: int, n_objects: int, *, size: int = 64) -> Any:
    """``image``: strided CNN on (B, C, 64, 64); ``points``: PointNet on (B, C, P); 9 outputs."""
    import torch
    from torch import nn

    class ImageNet(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            layers, c = [], channels
            for w in (16, 32, 64, 128):
                layers += [nn.Conv2d(c, w, 3, stride=2, padding=1, bias=False), nn.BatchNorm2d(w), nn.ReLU()]
                c = w
            self.features = nn.Sequential(*layers)
            self.head = nn.Sequential(
                nn.Linear(128 * (size // 16) ** 2 + n_objects, 128), nn.ReLU(), nn.Linear(128, 9)
            )

        def forward(self, x: torch.Tensor, onehot: torch.Tensor) -> torch.Tensor:
            f = self.features(x).flatten(1)
            return self.head(torch.cat([f, onehot], 1))

    class PointNet(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            layers, c = [], channels
            for w in (64, 128, 128):
                layers += [nn.Conv1d(c, w, 1, bias=False), nn.BatchNorm1d(w), nn.ReLU()]
                c = w
            self.features = nn.Sequential(*layers)
            self.head = nn.Sequential(nn.Linear(128 + n_objects, 128), nn.ReLU(), nn.Linear(128, 9))

        def forward(self, x: torch.Tensor, onehot: torch.Tensor) -> torch.Tensor:
            f = self.features(x).amax(2)
            return self.head(torch.cat([f, onehot], 1))

    return ImageNet() if kind == "image" else PointNet()


def to_pose(out: Any, base_t: Any, kind: str) -> tuple[Any, Any]:
    """Rotation (B, 3, 3) from two predicted columns (Gram-Schmidt) and translation (B, 3), m."""
    import torch

    a, b = out[:, 0:3], out[:, 3:6]
    c1 = torch.nn.functional.normalize(a + torch.tensor([1.0, 0.0, 0.0]), dim=1)
    b = b + torch.tensor([0.0, 1.0, 0.0])
    c2 = torch.nn.functional.normalize(b - (c1 * b).sum(1, keepdim=True) * c1, dim=1)
    c3 = torch.cross(c1, c2, dim=1)
    R = torch.stack([c1, c2, c3], 2)
    t = base_t + out[:, 6:9] * 0.1
    return R, t


def train_and_predict(
    kind: str,
    x_tr: np.ndarray,
    x_te: np.ndarray,
    data: dict,
    *,
    seed: int,
    epochs: int,
    batch: int = 32,
    lr: float = 2e-3,
) -> tuple[np.ndarray, np.ndarray]:
    """Train on the training views with the ADD loss; return the test (R, t) predictions."""
    import torch

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    n_obj = data["model_pts"].shape[0]
    model = make_model(kind, x_tr.shape[1], n_obj, size=x_tr.shape[-1])
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n = x_tr.shape[0]
    steps = epochs * -(-n // batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps)
    pts = torch.from_numpy(data["model_pts"])  # (O, P, 3)
    xt = torch.from_numpy(x_tr)
    onehot = torch.eye(n_obj)
    obj, R, t, base = (torch.from_numpy(data[k]) for k in ("obj_tr", "R_tr", "t_tr", "base_tr"))
    model.train()
    for _ in range(epochs):
        order = torch.randperm(n, generator=gen)
        for i in range(0, n, batch):
            j = order[i : i + batch]
            Rp, tp = to_pose(model(xt[j], onehot[obj[j]]), base[j], kind)
            p = pts[obj[j]]
            diff = p @ (Rp - R[j]).transpose(1, 2) + (tp - t[j])[:, None]
            loss = diff.norm(dim=2).mean() * 10.0
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
    model.eval()
    with torch.no_grad():
        Rp, tp = to_pose(
            model(torch.from_numpy(x_te), onehot[torch.from_numpy(data["obj_te"])]),
            torch.from_numpy(data["base_te"]),
            kind,
        )
    return Rp.numpy().astype(np.float64), tp.numpy().astype(np.float64)


# ---------------------------------------------------------------- scores


def pose_scores(
    Rp: np.ndarray, tp: np.ndarray, views: dict, eval_pts: np.ndarray, diameters: np.ndarray
) -> dict[str, float]:
    """ADD accuracy (< 10 % diameter), mean ADD (mm), rotation (deg) and translation (mm) errors,
    and the ADD accuracy of the predicted rotation with the true translation (the rotation's share)."""
    R, t, obj = views["R"].astype(np.float64), views["t"].astype(np.float64), views["obj"]
    p = eval_pts[obj]  # (N, P, 3)
    add = np.linalg.norm(p @ (Rp - R).transpose(0, 2, 1) + (tp - t)[:, None], axis=2).mean(1)
    cos = (np.einsum("nij,nij->n", Rp, R) - 1) / 2
    rot = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    tra = np.linalg.norm(tp - t, axis=1)
    add_r = np.linalg.norm(p @ (Rp - R).transpose(0, 2, 1), axis=2).mean(1)  # the true translation
    return {
        "add_acc": float(np.mean(add < 0.1 * diameters[obj])),
        "add_acc_true_t": float(np.mean(add_r < 0.1 * diameters[obj])),
        "add_mm": float(1000 * add.mean()),
        "rot_deg": float(rot.mean()),
        "rot_median_deg": float(np.median(rot)),
        "trans_mm": float(1000 * tra.mean()),
        "add_acc_per_object": [
            float(np.mean(add[obj == o] < 0.1 * diameters[o])) for o in range(len(diameters))
        ],
    }


METRICS = (
    ("add_acc", "ADD acc %", 100.0),
    ("add_mm", "mean ADD mm", 1.0),
    ("rot_deg", "rot err deg", 1.0),
    ("rot_median_deg", "median rot err deg", 1.0),
    ("trans_mm", "trans err mm", 1.0),
    ("add_acc_true_t", "ADD acc, true t %", 100.0),
)


def summarise(results: dict[str, dict[str, list[dict]]], errors: dict[str, float]) -> tuple[str, dict]:
    """Markdown table (mean +- std over seeds) and Welch p-values against each model's baseline."""
    lines = [
        "| model | input | "
        + " | ".join(f"{h} (mean +- std)" for _, h, _ in METRICS)
        + " | ADD acc per seed | p (ADD acc) vs rgb+depth or xyz+rgb | normal err on object (deg) |",
        "|---|---|" + "---:|" * len(METRICS) + "---|---:|---:|",
    ]
    pvals: dict[str, dict[str, float]] = {}
    for kind, by_input in results.items():
        ref = np.array([r["add_acc"] for r in by_input[BASELINE[kind]]]) * 100
        pvals[kind] = {}
        for name, runs in by_input.items():
            cells = []
            for key, _, scale in METRICS:
                a = np.array([r[key] for r in runs]) * scale
                cells.append(f"{a.mean():.2f} +- {objs.sd(a):.2f}")
            acc = np.array([r["add_acc"] for r in runs]) * 100
            p = objs.welch_p(acc, ref) if name != BASELINE[kind] else float("nan")
            pvals[kind][name] = p
            geo = objs.normal_source(name)
            err = f"{errors[geo]:.1f}" if geo in errors else "-"
            lines.append(
                f"| {kind} | {name} | " + " | ".join(cells) + f" | {' / '.join(f'{v:.1f}' for v in acc)} | "
                f"{'-' if np.isnan(p) else f'{p:.3f}'} | {err} |"
            )
    return "\n".join(lines), pvals


def figure(
    path: Path,
    views: dict,
    normals: dict[str, np.ndarray],
    preds: dict[str, tuple],
    K: dn.Intrinsics,
    eval_pts: np.ndarray,
    picks: list[int],
) -> None:
    """Rows: test views; columns: colour, depth, the normals, and each image input's pose (seed 0)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def proj(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return K.fx * P[:, 0] / P[:, 2] + K.cx, K.fy * P[:, 1] / P[:, 2] + K.cy

    cols = ["colour + true pose", "noisy depth", *[f"{m} normals" for m in normals], *preds]
    fig, axes = plt.subplots(
        len(picks), len(cols), figsize=(1.9 * len(cols), 1.9 * len(picks) + 0.3), squeeze=False
    )
    for r, i in enumerate(picks):
        o = views["obj"][i]
        true = eval_pts[o] @ views["R"][i].T.astype(np.float64) + views["t"][i]
        rgb = views["rgb"][i].transpose(1, 2, 0)
        panels: list[tuple[np.ndarray, np.ndarray | None, str]] = [(rgb, true, "")]
        panels.append((views["depth"][i], None, objs.SENSORS[views["sensor"][i]]))
        for n in normals.values():
            panels.append((np.clip((n[i].transpose(1, 2, 0) * [1, -1, -1] + 1) / 2, 0, 1), None, ""))
        for Rp, tp in preds.values():
            P = eval_pts[o] @ Rp[i].T + tp[i]
            add = np.linalg.norm(P - true, axis=1).mean() * 1000
            panels.append((rgb, P, f"ADD {add:.0f} mm"))
        for c, (img, P, text) in enumerate(panels):
            ax = axes[r, c]
            ax.imshow(img, cmap="viridis" if img.ndim == 2 else None, interpolation="nearest")
            if P is not None:
                u, v = proj(P)
                ax.plot(u, v, ".", ms=1.0, color="lime" if c == 0 else "red", alpha=0.7)
            ax.set_xlim(-0.5, img.shape[1] - 0.5)
            ax.set_ylim(img.shape[0] - 0.5, -0.5)
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(cols[c], fontsize=7)
            if text:
                ax.text(1, 6, text, color="white", fontsize=6)
            if c == 0:
                ax.set_ylabel(objs.OBJECTS[o], fontsize=7)
    fig.suptitle(
        "green: model points under the true pose; red: under the image model's pose (seed 0)", fontsize=8
    )
    objs.save_figure(fig, path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--train", type=int, default=1600, help="training views (default 1600)")
    p.add_argument("--test", type=int, default=400, help="test views (default 400)")
    p.add_argument("--size", type=int, default=64, help="image side, px (default 64; a multiple of 16)")
    p.add_argument("--epochs", type=int, default=20, help="epochs of the image model (default 20)")
    p.add_argument("--point-epochs", type=int, default=20, help="epochs of the point model (default 20)")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--models", default="image,points")
    p.add_argument("--image-inputs", default=",".join(DEFAULT_IMAGE))
    p.add_argument("--point-inputs", default=",".join(POINT_INPUTS))
    p.add_argument("--clean", action="store_true", help="exact rendered depth, no sensor noise")
    p.add_argument("--threads", type=int, default=1, help="torch and library threads (default 1)")
    p.add_argument(
        "--cache",
        type=Path,
        default=Path("/tmp/depthnormals-bench"),
        help="folder of the rendered views (reused by later runs)",
    )
    p.add_argument("--out", type=Path, help="markdown table (and a .json sidecar beside it)")
    p.add_argument("--figure", type=Path, help="PNG of a few test views with the predicted poses")
    args = p.parse_args(argv)
    if args.size % 16:
        p.error("--size must be a multiple of 16 (four stride-2 layers)")
    import torch

    torch.set_num_threads(args.threads)
    dn.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    models = tuple(m for m in args.models.split(",") if m)
    inputs = {"image": tuple(args.image_inputs.split(",")), "points": tuple(args.point_inputs.split(","))}
    for kind, valid in (("image", IMAGE_INPUTS), ("points", POINT_INPUTS)):
        bad = [n for n in inputs[kind] if n not in valid]
        if bad:
            p.error(f"unknown {kind} input(s) {bad}; valid: {', '.join(valid)}")
    if set(models) - {"image", "points"}:
        p.error("--models takes image, points or both")
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", flush=True)

    log(
        f"views: {args.train} train + {args.test} test, {args.size}x{args.size}, "
        f"objects {', '.join(objs.OBJECTS)}"
    )
    tr, te, K, n_tr, n_te, errors = objs.views_and_normals(args, [n for k in models for n in inputs[k]], log)
    model_pts = np.stack([objs.surface_points(o, LOSS_POINTS, seed=1) for o in objs.OBJECTS]).astype(
        np.float32
    )
    eval_pts = np.stack([objs.surface_points(o, 500, seed=2) for o in objs.OBJECTS])
    diameters = np.array([np.linalg.norm(e[:, None] - e[None], axis=2).max() for e in eval_pts])
    results: dict[str, dict[str, list[dict]]] = {}
    preds: dict[str, tuple] = {}
    for kind in models:
        if kind == "image":
            x_tr, x_te = image_inputs(tr, n_tr, inputs[kind]), image_inputs(te, n_te, inputs[kind])
            base_tr = np.tile(np.float32([0, 0, DEPTH_CENTRE]), (args.train, 1))
            base_te = np.tile(np.float32([0, 0, DEPTH_CENTRE]), (args.test, 1))
        else:
            x_tr, base_tr = point_inputs(tr, n_tr, inputs[kind], K, seed=0)
            x_te, base_te = point_inputs(te, n_te, inputs[kind], K, seed=1)
        data = {
            "model_pts": model_pts,
            "obj_tr": tr["obj"],
            "R_tr": tr["R"],
            "t_tr": tr["t"],
            "base_tr": base_tr,
            "obj_te": te["obj"],
            "base_te": base_te,
        }
        epochs = args.epochs if kind == "image" else args.point_epochs
        results[kind] = {}
        for name in inputs[kind]:
            results[kind][name] = []
            for seed in range(args.seeds):
                t = time.perf_counter()
                Rp, tp = train_and_predict(kind, x_tr[name], x_te[name], data, seed=seed, epochs=epochs)
                s = pose_scores(Rp, tp, te, eval_pts, diameters)
                s.update(
                    seed=seed, channels=int(x_tr[name].shape[1]), seconds=round(time.perf_counter() - t, 1)
                )
                results[kind][name].append(s)
                if seed == 0 and kind == "image":
                    preds[name] = (Rp, tp)
                log(
                    f"{kind:<6} {name:<14} seed {seed}: ADD acc {100 * s['add_acc']:.1f} % "
                    f"ADD {s['add_mm']:.1f} mm "
                    f"rot {s['rot_deg']:.1f} deg trans {s['trans_mm']:.1f} mm ({s['seconds']:.0f} s)"
                )
    table, pvals = summarise(results, errors)
    wall = time.perf_counter() - t0
    print(table)
    print(f"wall time {wall:.0f} s")
    if args.out:
        objs.write_report(args.out, table, args, K, wall=wall, errors=errors,
                          diameters_mm=[round(1000 * d, 1) for d in diameters],
                          p_add_acc_vs_depth=pvals, results=results)
    if args.figure and preds:
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        picks = [int(np.flatnonzero(te["obj"] == o)[0]) for o in range(min(4, len(objs.OBJECTS)))]
        figure(args.figure, te, {m: n_te[m] for m in n_te}, preds, K, eval_pts, picks)
        log(f"figure written to {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
