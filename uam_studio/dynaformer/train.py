"""Training loop for the Dynaformer: synthetic data, bucketed batches, checkpoints, resume."""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from .artifact import atomic_torch_save, save_artifact
from .data import DischargeSet, make_dataset
from .model import Dynaformer, DynaformerConfig

DEFAULT_CONTEXT_S = 20


@dataclass
class TrainConfig:
    n_train: int = 24000
    steps: int = 5000
    batch: int = 32
    lr: float = 1e-3
    seed: int = 0
    max_len: int = 10240  # samples on the 1 s grid
    checkpoint_every: int = 500
    device: str = "auto"
    threads: int = 0  # 0: torch default


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def sample_context_lengths(rng: np.random.Generator, n: int) -> np.ndarray:
    """Mostly the paper's 20 s; sometimes longer (up to 600 s) so any length up to the history works."""
    long = rng.random(n) < 0.4
    return np.where(long, rng.integers(20, 601, n), DEFAULT_CONTEXT_S)


def make_batch(ds: DischargeSet, idx: np.ndarray, rng: np.random.Generator, chunk: int, device,
               noise: bool = True):
    """Tensors for one batch: context (with sensor noise), profile, targets and loss weights."""
    n_valid = ds.valid[idx].sum(1)
    t = int(math.ceil(max(int(n_valid.max()), chunk) / chunk) * chunk)
    t = min(t, ds.current_a.shape[1] // chunk * chunk)
    cur = ds.current_a[idx, :t]
    volt = ds.voltage_v[idx, :t]
    valid = ds.valid[idx, :t]
    lens = np.minimum(sample_context_lengths(rng, idx.size), np.maximum(n_valid, 1))
    lmax = int(lens.max())
    ctx_i = cur[:, :lmax].copy()
    ctx_v = volt[:, :lmax].copy()
    ctx_mask = np.arange(lmax)[None, :] < lens[:, None]
    if noise:
        sig_v = np.where(rng.random(idx.size) < 0.5, 0.0, rng.uniform(0.0, 0.010, idx.size))
        ctx_v = ctx_v + rng.normal(size=ctx_v.shape) * sig_v[:, None]
        ctx_i = ctx_i + rng.normal(size=ctx_i.shape) * 0.005
    # Weight the region around the 3.0 V cut-off more: it decides the EOD time.
    weight = valid * (1.0 + 3.0 * ((volt > 2.8) & (volt < 3.3)))
    as_t = lambda a, dt=torch.float32: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=device)  # noqa: E731
    return (as_t(ctx_i), as_t(ctx_v), as_t(ctx_mask, torch.bool), as_t(cur), as_t(volt), as_t(weight))


class BucketSampler:
    """Batches of similar profile length (sorted into buckets), so padding stays small."""

    def __init__(self, lengths: np.ndarray, batch: int, rng: np.random.Generator, n_buckets: int = 24):
        order = np.argsort(lengths, kind="stable")
        n_buckets = max(1, min(n_buckets, lengths.size // batch))
        self.buckets = [b for b in np.array_split(order, n_buckets) if b.size >= batch]
        self.batch, self.rng = batch, rng

    def __call__(self) -> np.ndarray:
        b = self.buckets[int(self.rng.integers(len(self.buckets)))]
        return self.rng.choice(b, self.batch, replace=False)


@torch.no_grad()
def fit_pca(model: Dynaformer, ds: DischargeSet, device, context_s: int = DEFAULT_CONTEXT_S) -> dict:
    """PCA (2 components) of the health latent over 20 s contexts of the training data."""
    model.eval()
    lat = []
    for s in range(0, len(ds), 1024):
        ci = torch.as_tensor(ds.current_a[s:s + 1024, :context_s], device=device)
        cv = torch.as_tensor(ds.voltage_v[s:s + 1024, :context_s], device=device)
        lat.append(model.encode(ci, cv).cpu().double())
    z = torch.cat(lat)
    mean = z.mean(0)
    _, s_vals, vh = torch.linalg.svd(z - mean, full_matrices=False)
    comps = vh[:2]
    scores = (z - mean) @ comps.T
    scale = scores.std(0)
    explained = (s_vals[:2] ** 2 / (s_vals ** 2).sum())
    return {"mean": mean.float(), "components": comps.float(), "scale": scale.float(), "explained": explained.float()}


def train(cfg: TrainConfig, out_dir, resume: bool = True, model_cfg: DynaformerConfig | None = None,
          callback=None) -> Path:
    """Train from scratch (or resume from ``out_dir/checkpoint.pt``); write ``out_dir/dynaformer.pt``.

    :param cfg: training settings.
    :param out_dir: run folder (never the bundled ``pretrained/`` folder).
    :param callback: optional ``f(step, loss)``.
    :return: path of the exported weights.
    """
    model_cfg = model_cfg or DynaformerConfig()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    device = pick_device(cfg.device)
    torch.manual_seed(cfg.seed)
    t_start = time.perf_counter()
    cache = out / f"train_data_seed{cfg.seed}_n{cfg.n_train}.npz"
    if cache.exists():
        ds = DischargeSet.load(cache)
    else:
        ds = make_dataset(cfg.n_train, seed=cfg.seed, max_len=cfg.max_len)
        ds.save(cache)
    t_data = time.perf_counter() - t_start
    model = Dynaformer(model_cfg).to(device)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=1e-4)
    warm = 300
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: min(1.0, (s + 1) / warm) * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(s, cfg.steps) / cfg.steps))))
    step, elapsed_before = 0, 0.0
    ckpt_path = out / "checkpoint.pt"
    if resume and ckpt_path.exists():
        ck = torch.load(ckpt_path, map_location=device, weights_only=False)
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["opt"])
        sched.load_state_dict(ck["sched"])
        step, elapsed_before = ck["step"], ck.get("train_s", 0.0)
        np_state = ck["rng"]
    else:
        np_state = None
    rng = np.random.default_rng(cfg.seed + 1)
    if np_state is not None:
        rng.bit_generator.state = np_state
    sampler = BucketSampler(ds.valid.sum(1), cfg.batch, rng)
    model.train()
    t0 = time.perf_counter()
    bar = tqdm(total=cfg.steps, initial=step, desc="dynaformer", unit="step", mininterval=5.0)
    ema = None
    while step < cfg.steps:
        ci, cv, cm, cur, volt, w = make_batch(ds, sampler(), rng, model_cfg.chunk, device)
        pred = model(ci, cv, cur, cm)
        loss = (w * (pred - volt) ** 2).sum() / w.sum().clamp_min(1.0)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        sched.step()
        step += 1
        lv = float(loss.detach())
        ema = lv if ema is None else 0.98 * ema + 0.02 * lv
        bar.update(1)
        if step % 50 == 0:
            bar.set_postfix(rmse_mv=f"{1000 * math.sqrt(ema):.1f}")
        if callback:
            callback(step, lv)
        if step % cfg.checkpoint_every == 0 or step == cfg.steps:
            atomic_torch_save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                               "step": step, "rng": rng.bit_generator.state,
                               "train_s": elapsed_before + time.perf_counter() - t0}, ckpt_path)
    bar.close()
    train_s = elapsed_before + time.perf_counter() - t0
    pca = fit_pca(model, ds, device)
    meta = {"train_config": asdict(cfg), "train_seconds": round(train_s, 1), "data_seconds": round(t_data, 1),
            "device": str(device), "torch_threads": torch.get_num_threads(), "final_rmse_mv_ema": 1000 * math.sqrt(ema or 0)}
    weights = out / "dynaformer.pt"
    save_artifact(weights, model.cpu(), pca, meta)
    (out / "train_meta.json").write_text(json.dumps(meta, indent=2))
    return weights
