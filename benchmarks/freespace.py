"""Freespace detection with and without surface normals (the 3F2N+ paper, section V; issue 16).

Data: car-like views of the procedural road scenes with a freespace label and sensor noise
(:mod:`depthnormals.synth.freespace`); the test frames come from other scene instances than
the training frames. Model: a small U-Net (three levels, 8-16-32 channels by default, batch norm),
trained on the CPU with Adam and a binary cross-entropy loss. Inputs, one network each:

- ``disparity``: inverse depth 1/z (1/m), 0 where the sensor returns nothing;
- ``3f2n+``: normals of ``depthnormals.torch.EstimateNormals("3f2n+", invalid="zero")``
  (the torch backend as the data transform, its defaults);
- ``fals``: normals of the FALS peer through the registry (``depthnormals.estimate_normals``);
- ``disparity+3f2n+``: both, 4 channels;
- ``3f2n+numba``: normals of ``depthnormals.estimate_normals(method="3f2n+")``, the numba
  library's default (``selection="auto"``: a box-fit of inverse depth on noisy depth, which
  the torch path does not implement; docs/torch.md), for comparison.

Each input is trained from ``--seeds`` seeds (initialisation and batch order; the data are the
same for every seed); scores are pooled over the test pixels (IoU, F1) and reported as the
mean and the sample standard deviation over seeds.

    PYTHONPATH=src python3 benchmarks/freespace.py --out /tmp/freespace.md \\
        --figure docs/figures/freespace.png

Defaults: 64x128 px, 160 training and 80 test frames, 14 epochs, 3 seeds, one torch thread,
Gaussian noise sigma = 0.5 z/f; about 7-11 minutes on the shared 2-core machine
(docs/benchmarks.md section 13).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

import depthnormals as dn
from depthnormals.io import atomic_write, write_bytes_atomic
from depthnormals.synth.freespace import RoadFrame, road_frames, segmentation_scores

INPUTS = ("disparity", "3f2n+", "fals", "disparity+3f2n+", "3f2n+numba")


# ---------------------------------------------------------------- inputs

def disparity(frames: list[RoadFrame]) -> np.ndarray:
    """(N, 1, H, W) float32 inverse depth, 1/m, 0 where there is no depth."""
    d = np.stack([f.depth for f in frames])
    return np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0).astype(np.float32)[:, None]


def torch_normals(frames: list[RoadFrame], *, method: str = "3f2n+", chunk: int = 16) -> np.ndarray:
    """(N, 3, H, W) float32 normals of the torch backend, 0 where none (the data transform)."""
    import torch

    from depthnormals.torch import EstimateNormals

    K = frames[0].K
    transform = EstimateNormals(method, K=torch.tensor([K.fx, K.fy, K.cx, K.cy]), invalid="zero")
    out = []
    with torch.no_grad():
        for i in range(0, len(frames), chunk):
            depth = torch.from_numpy(np.stack([f.depth for f in frames[i:i + chunk]]))[:, None]
            out.append(transform(depth).numpy())
    return np.concatenate(out).astype(np.float32)


def registry_normals(frames: list[RoadFrame], *, method: str = "fals") -> np.ndarray:
    """(N, 3, H, W) float32 normals of a registry estimator (numba), 0 where none."""
    n = dn.estimate_normals(np.stack([f.depth for f in frames]), frames[0].K, method=method)
    return np.nan_to_num(n).transpose(0, 3, 1, 2).astype(np.float32)


def build_inputs(frames: list[RoadFrame], names: tuple[str, ...] = INPUTS) -> dict[str, np.ndarray]:
    """Every input named in ``names`` as (N, C, H, W) float32, each transform computed once."""
    parts: dict[str, np.ndarray] = {}
    out = {}
    for name in names:
        chans = []
        pieces = ["disparity", "3f2n+"] if name == "disparity+3f2n+" else [name]
        for piece in pieces:
            if piece not in parts:
                if piece == "disparity":
                    parts[piece] = disparity(frames)
                elif piece == "3f2n+":
                    parts[piece] = torch_normals(frames, method="3f2n+")
                elif piece == "3f2n+numba":
                    parts[piece] = registry_normals(frames, method="3f2n+")
                else:
                    parts[piece] = registry_normals(frames, method=piece)
            chans.append(parts[piece])
        out[name] = np.concatenate(chans, axis=1)
    return out


def normal_error(frames: list[RoadFrame], normals: np.ndarray) -> float:
    """Mean angular error (deg) of (N, 3, H, W) normals against the ground truth, where both exist."""
    est = normals.transpose(0, 2, 3, 1).astype(np.float64)
    gt = np.stack([f.normals for f in frames]).astype(np.float64)
    ok = np.isfinite(gt).all(-1) & (np.abs(est).sum(-1) > 0)
    e = dn.angular_error(est[ok][None], gt[ok][None])
    return float(np.mean(e))


# ---------------------------------------------------------------- model and training

def make_unet(in_channels: int, *, width: int = 16) -> Any:
    """A three-level U-Net (width, 2 width, 4 width channels), one logit per pixel."""
    import torch
    from torch import nn

    def block(a: int, b: int) -> nn.Sequential:
        return nn.Sequential(nn.Conv2d(a, b, 3, padding=1, bias=False), nn.BatchNorm2d(b), nn.ReLU(),
                             nn.Conv2d(b, b, 3, padding=1, bias=False), nn.BatchNorm2d(b), nn.ReLU())

    class TinyUNet(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            w = width
            self.e1, self.e2, self.e3 = block(in_channels, w), block(w, 2 * w), block(2 * w, 4 * w)
            self.d2, self.d1 = block(4 * w + 2 * w, 2 * w), block(2 * w + w, w)
            self.head = nn.Conv2d(w, 1, 1)
            self.pool = nn.MaxPool2d(2)
            self.up = nn.Upsample(scale_factor=2, mode="bilinear", align_corners=False)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            a = self.e1(x)
            b = self.e2(self.pool(a))
            c = self.e3(self.pool(b))
            b = self.d2(torch.cat([self.up(c), b], 1))
            return self.head(self.d1(torch.cat([self.up(b), a], 1)))

    return TinyUNet()


def train(x: np.ndarray, y: np.ndarray, *, seed: int, epochs: int, batch: int = 8, lr: float = 2e-3,
          width: int = 16, max_steps: int | None = None, log: Any = None) -> Any:
    """Train a U-Net on inputs ``x`` (N, C, H, W) and labels ``y`` (N, H, W) bool; returns it (eval mode)."""
    import torch

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    model = make_unet(x.shape[1], width=width)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    steps_per_epoch = -(-x.shape[0] // batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=epochs * steps_per_epoch)
    loss_fn = torch.nn.BCEWithLogitsLoss()
    xt, yt = torch.from_numpy(x), torch.from_numpy(y.astype(np.float32))[:, None]
    model.train()
    step = 0
    for epoch in range(epochs):
        order = torch.randperm(x.shape[0], generator=gen)
        total = 0.0
        for i in range(0, x.shape[0], batch):
            idx = order[i:i + batch]
            opt.zero_grad()
            loss = loss_fn(model(xt[idx]), yt[idx])
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
            step += 1
            if max_steps is not None and step >= max_steps:
                return model.eval()
        if log is not None:
            log(f"    epoch {epoch + 1}/{epochs} loss {total / x.shape[0]:.4f}")
    return model.eval()


def predict(model: Any, x: np.ndarray, *, batch: int = 16) -> np.ndarray:
    """(N, H, W) bool: logit > 0."""
    import torch

    out = []
    with torch.no_grad():
        for i in range(0, x.shape[0], batch):
            out.append((model(torch.from_numpy(x[i:i + batch]))[:, 0] > 0).numpy())
    return np.concatenate(out)


# ---------------------------------------------------------------- report

def _sd(a: np.ndarray) -> float:
    return float(np.std(a, ddof=1)) if a.size > 1 else float("nan")


def summarise(results: dict[str, list[dict]], errors: dict[str, float]) -> str:
    """Markdown table: IoU and F1 (%) per input, mean +- sample std over seeds, and per seed."""
    lines = ["| input | channels | IoU % (mean +- std) | F1 % (mean +- std) | IoU per seed | "
             "normal error on test (deg) |",
             "|---|---:|---:|---:|---|---:|"]
    for name, runs in results.items():
        iou = np.array([r["iou"] for r in runs]) * 100
        f1 = np.array([r["f1"] for r in runs]) * 100
        err = f"{errors[name]:.1f}" if name in errors else "-"
        lines.append(f"| {name} | {runs[0]['channels']} | {iou.mean():.2f} +- {_sd(iou):.2f} | "
                     f"{f1.mean():.2f} +- {_sd(f1):.2f} | {' / '.join(f'{v:.2f}' for v in iou)} | {err} |")
    return "\n".join(lines)


def figure(path: Path, frames: list[RoadFrame], inputs: dict[str, np.ndarray],
           preds: dict[str, np.ndarray], picks: list[int]) -> None:
    """Rows: test frames; columns: disparity, 3F2N+ normals, label, each input's prediction (seed 0)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = ["noisy disparity", "3f2n+ normals", "freespace label", *[f"pred: {k}" for k in preds]]
    fig, axes = plt.subplots(len(picks), len(cols), figsize=(2.3 * len(cols), 1.35 * len(picks) + 0.4),
                             squeeze=False)
    for r, i in enumerate(picks):
        label = frames[i].label
        n = inputs["3f2n+"][i] if "3f2n+" in inputs else inputs["disparity+3f2n+"][i, 1:]
        images = [inputs["disparity"][i, 0] if "disparity" in inputs else 1.0 / frames[i].depth,
                  np.clip((np.moveaxis(n, 0, -1) * [1, -1, -1] + 1) / 2, 0, 1), label]
        for k in preds:
            p = preds[k][i]
            rgb = np.zeros((*p.shape, 3))
            rgb[p & label] = (0.2, 0.8, 0.2)   # true positive
            rgb[p & ~label] = (0.9, 0.2, 0.2)  # false positive
            rgb[~p & label] = (0.2, 0.3, 0.9)  # false negative
            s = segmentation_scores(p, label)
            images.append((rgb, f"IoU {100 * s['iou']:.1f}"))
        for c, img in enumerate(images):
            ax = axes[r, c]
            text = None
            if isinstance(img, tuple):
                img, text = img
            ax.imshow(img, cmap="viridis" if img.ndim == 2 and c == 0 else "gray", interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(cols[c], fontsize=8)
            if text:
                ax.text(2, 10, text, color="white", fontsize=7)
            if c == 0:
                ax.set_ylabel(frames[i].scene.split("/")[0], fontsize=7)
    fig.suptitle("green: freespace found, red: false freespace, blue: missed", fontsize=8)
    fig.tight_layout()
    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)


def parse_size(text: str) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--size must look like 128x256 (HxW); got {text!r}") from exc
    if h % 4 or w % 4:
        raise argparse.ArgumentTypeError(f"--size must be divisible by 4 (two poolings); got {text!r}")
    return h, w


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", type=parse_size, default=(64, 128), help="HxW (default 64x128)")
    p.add_argument("--train", type=int, default=160, help="training frames")
    p.add_argument("--test", type=int, default=80, help="held-out frames (other scene instances)")
    p.add_argument("--epochs", type=int, default=14)
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--width", type=int, default=8, help="channels of the first U-Net level")
    p.add_argument("--noise", default="gaussian:sigma_px=0.5", help="sensor model spec or 'none'")
    p.add_argument("--inputs", default=",".join(INPUTS))
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads (1: on a shared 2-core machine 2 threads ran 2-4x slower)")
    p.add_argument("--out", type=Path, help="markdown table (and a .json sidecar beside it)")
    p.add_argument("--figure", type=Path, help="PNG of a few test predictions")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    names = tuple(args.inputs.split(","))
    bad = [n for n in names if n not in INPUTS]
    if bad:
        p.error(f"unknown input(s) {bad}; valid: {', '.join(INPUTS)}")
    noise = None if args.noise == "none" else args.noise
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", flush=True)

    log(f"rendering {args.train} + {args.test} frames {args.size[0]}x{args.size[1]}, noise {noise}")
    train_frames = road_frames(args.train, seed=0, size=args.size, noise=noise)
    test_frames = road_frames(args.test, seed=1, size=args.size, noise=noise)
    y_train = np.stack([f.label for f in train_frames])
    y_test = np.stack([f.label for f in test_frames])
    log(f"freespace share: train {y_train.mean():.3f}, test {y_test.mean():.3f}; computing inputs")
    x_train, x_test = build_inputs(train_frames, names), build_inputs(test_frames, names)
    errors = {k: normal_error(test_frames, v[:, -3:]) for k, v in x_test.items() if v.shape[1] >= 3}
    log("normal error on test (deg): " + ", ".join(f"{k} {v:.2f}" for k, v in errors.items()))
    results: dict[str, list[dict]] = {}
    preds: dict[str, np.ndarray] = {}
    for name in names:
        results[name] = []
        for seed in range(args.seeds):
            t = time.perf_counter()
            model = train(x_train[name], y_train, seed=seed, epochs=args.epochs, width=args.width)
            pred = predict(model, x_test[name])
            s = segmentation_scores(pred, y_test)
            s.update(seed=seed, channels=int(x_train[name].shape[1]), seconds=time.perf_counter() - t)
            results[name].append(s)
            if seed == 0:
                preds[name] = pred
            log(f"{name:<16} seed {seed}: IoU {100 * s['iou']:.2f} F1 {100 * s['f1']:.2f} "
                f"({s['seconds']:.0f} s)")
    table = summarise(results, errors)
    wall = time.perf_counter() - t0
    print(table)
    print(f"wall time {wall:.0f} s")
    if args.out:
        write_bytes_atomic(args.out, (table + "\n").encode())
        meta = {"settings": {k: (list(v) if isinstance(v, tuple) else str(v) if isinstance(v, Path) else v)
                             for k, v in vars(args).items()},
                "depthnormals": dn.__version__, "torch": torch.__version__, "machine": platform.machine(),
                "processor": platform.processor(), "wall_s": round(wall, 1),
                "train_freespace_share": float(y_train.mean()), "test_freespace_share": float(y_test.mean()),
                "normal_error_deg": errors, "results": results}
        write_bytes_atomic(args.out.with_suffix(".json"), (json.dumps(meta, indent=1) + "\n").encode())
    if args.figure:
        recipes = [f.scene.split("/")[0] for f in test_frames]
        picks = [recipes.index(r) for r in dict.fromkeys(recipes)]  # the first test frame of each recipe
        figure(args.figure, test_frames, x_test, preds, picks)
        log(f"figure written to {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
