"""Training loop for the Dynaformer: synthetic data, bucketed batches, checkpoints, resume.

With the default take-off health estimator (``DynaformerConfig.health == "takeoff"``):

1. :func:`fit_takeoff_health`: closed-form least squares of :class:`TakeoffHealth` on the
   noise-free first ``health_window`` s of the ``n_context`` extra cells (about 15 s).
2. ``steps``: the decoder learns the voltage of whole discharges from that 2-D health
   estimate of each discharge's own noise-free take-off (weighted MSE, 4x near EOD).

With the ``"transformer"`` encoder, two stages:

1. ``encoder_steps``: the encoder and health head: the 2-D health embedding regresses
   the cell's R0 normalised to [-1, 1] and q_max normalised to [-0.5, 0.5] (so R0
   carries the larger spread and PC1 follows R0, PC2 q_max, as in the paper), from short contexts
   (20-120 s, with sensor noise) of ``n_context`` cheap extra discharges. q_max's signature in 20 s is a few
   millivolts on top of R0's hundreds; trained jointly with the decoder, the
   encoder never found it, and joint training after this stage erased it again.
2. ``steps``: the encoder is frozen and the decoder learns the voltage of whole
   discharges from the health latent: weighted MSE (4x weight near the 3.0 V EOD).
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from uam_studio.errors import InputError

from ..atomic_io import remove_stale_temps
from ..flight import TAKEOFF_CONTEXT_S
from ..tensor_files import TensorFileError, load_tensors
from .artifact import atomic_torch_save, save_artifact
from .data import TRAIN_Q_RANGE, DischargeSet, make_dataset
from .model import R0_HALF as R_HALF
from .model import R0_MID as R_MID
from .model import Dynaformer, DynaformerConfig, takeoff_targets

DEFAULT_CONTEXT_S = TAKEOFF_CONTEXT_S  # s: the take-off context (uam_studio.flight.context)
ENCODER_PARTS = ("enc_in", "encoder", "to_latent", "health_head")  # trained in stage 1, frozen in stage 2
CONTEXT_SET_LEN = 600  # samples (s) of each extra short-context cell
CONTEXT_BATCH_MAX_S = 120  # s: the extra context batch stays short (cheap); discharges carry the long ones
Q_MID, Q_HALF = sum(TRAIN_Q_RANGE) / 2, (TRAIN_Q_RANGE[1] - TRAIN_Q_RANGE[0]) / 2  # C
Q_LATENT_SPREAD = 0.5  # q_max's half-range in the latent, R0's is 1


@dataclass
class TrainConfig:
    n_train: int = 24000
    n_context: int = 96000  # extra short-context cells (stage 1)
    context_batch: int = 256
    encoder_steps: int = 10000  # stage 1: encoder + health head only
    steps: int = 60000  # decoder steps (the second stage, see the module docstring)
    batch: int = 32
    lr: float = 1e-3
    seed: int = 0
    max_len: int | None = None  # samples on the 1 s grid; default the cell type's (10240 for the NASA cell)
    checkpoint_every: int = 500
    device: str = "auto"
    threads: int = 0  # 0: torch default
    takeoff_ridge: float = 1e-8  # ridge of the take-off health fit, x n_cells, on standardised features
    cell: str = "nasa18650"  # the cell type trained for (uam_studio.dynaformer.cells)
    init: str | None = None  # weights file to fine-tune from (its decoder; the take-off fit is redone)


def pick_device(name: str) -> torch.device:
    """The torch device for ``name``: ``auto`` (CUDA when available, else CPU), ``cpu``, ``cuda`` or ``cuda:N``.

    :raises InputError: (field ``device``) for another name, or CUDA where torch sees no CUDA device.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError):
        dev = None
    if dev is None or dev.type not in ("cpu", "cuda"):
        raise InputError("device", f"{name!r} is not a device; allowed: auto, cpu, cuda, cuda:N")
    if dev.type == "cuda":
        n = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if n == 0 or (dev.index or 0) >= n:
            raise InputError("device", f"{name!r}: torch sees {n} CUDA devices here; use auto or cpu")
    return dev


def sample_context_lengths(rng: np.random.Generator, n: int, max_s: int = 600) -> np.ndarray:
    """Mostly the paper's 20 s; sometimes longer (up to ``max_s``) so any length up to the history works."""
    long = rng.random(n) < 0.4
    return np.where(long, rng.integers(DEFAULT_CONTEXT_S, max_s + 1, n), DEFAULT_CONTEXT_S)


def health_targets(ds: DischargeSet, idx: np.ndarray) -> np.ndarray:
    """Stage-1 latent targets [len(idx), 2]: R0 on [-1, 1] and q_max on [-0.5, 0.5] over the
    training ranges (ohm, C)."""
    r = (ds.r0[idx] - R_MID) / R_HALF
    q = Q_LATENT_SPREAD * (ds.q_max[idx] - Q_MID) / Q_HALF
    return np.stack([r, q], 1).astype(np.float32)


def noisy_context(ds: DischargeSet, idx: np.ndarray, rng: np.random.Generator, noise: bool = True,
                  max_s: int = 600):
    """Context current (A), voltage (V) and mask [B, L] of random length (mostly 20 s, at most
    ``max_s``), with sensor noise (none on half the cells, else up to 10 mV)."""
    n_valid = ds.valid[idx].sum(1)
    lens = np.minimum(sample_context_lengths(rng, idx.size, max_s), np.maximum(n_valid, 1))
    lmax = int(lens.max())
    ctx_i: np.ndarray = ds.current_a[idx, :lmax].astype(np.float32)  # float64 once noise is added
    ctx_v: np.ndarray = ds.voltage_v[idx, :lmax].astype(np.float32)
    ctx_mask = np.arange(lmax)[None, :] < lens[:, None]
    if noise:
        sig_v = np.where(rng.random(idx.size) < 0.5, 0.0, rng.uniform(0.0, 0.010, idx.size))
        ctx_v = ctx_v + rng.normal(size=ctx_v.shape) * sig_v[:, None]
        ctx_i = ctx_i + rng.normal(size=ctx_i.shape) * 0.005
    return ctx_i, ctx_v, ctx_mask


def _tensor(a, device, dtype=torch.float32) -> torch.Tensor:
    return torch.as_tensor(np.ascontiguousarray(a), dtype=dtype, device=device)


def make_batch(ds: DischargeSet, idx: np.ndarray, rng: np.random.Generator, chunk: int, device,
               noise: bool = True):
    """Tensors for one batch: context (with sensor noise), profile, targets and loss weights."""
    n_valid = ds.valid[idx].sum(1)
    t = int(math.ceil(max(int(n_valid.max()), chunk) / chunk) * chunk)
    t = min(t, ds.current_a.shape[1] // chunk * chunk)
    cur = ds.current_a[idx, :t]
    volt = ds.voltage_v[idx, :t]
    valid = ds.valid[idx, :t]
    ctx_i, ctx_v, ctx_mask = noisy_context(ds, idx, rng, noise)
    # Weight the region around the 3.0 V cut-off more: it decides the EOD time.
    weight = valid * (1.0 + 3.0 * ((volt > 2.8) & (volt < 3.3)))
    return (_tensor(ctx_i, device), _tensor(ctx_v, device), _tensor(ctx_mask, device, torch.bool),
            _tensor(cur, device), _tensor(volt, device), _tensor(weight, device))


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


def _cached_dataset(path: Path, n: int, seed: int, max_len: int | None, cell: str = "nasa18650") -> DischargeSet:
    """make_dataset, cached as .npz in the run folder (git-ignored ``runs/``), written atomically.

    A cache that cannot be read (truncated or corrupt, e.g. by a kill under an older version) or
    holds another number of discharges is reported in one line on stderr and regenerated.
    """
    if path.exists():
        try:
            ds = DischargeSet.load(path)
        except ValueError as exc:
            print(f"warning: {exc}; regenerating it", file=sys.stderr)
        else:
            if len(ds) == n:
                return ds
            print(f"warning: {path}: holds {len(ds)} discharges, not {n}; regenerating it", file=sys.stderr)
    ds = make_dataset(n, seed=seed, max_len=max_len, cell=cell)
    ds.save(path)
    return ds


@torch.no_grad()
def fit_pca(model: Dynaformer, ds: DischargeSet, device, context_s: int = DEFAULT_CONTEXT_S) -> dict:
    """PCA (2 components) of the health embedding over 20 s contexts of the training data."""
    model.eval()
    lat = []
    for s in range(0, len(ds), 1024):
        ci = torch.as_tensor(ds.current_a[s:s + 1024, :context_s], device=device)
        cv = torch.as_tensor(ds.voltage_v[s:s + 1024, :context_s], device=device)
        lat.append(model.health_head(model.encode(ci, cv)).cpu().double())
    z = torch.cat(lat)
    mean = z.mean(0)
    _, s_vals, vh = torch.linalg.svd(z - mean, full_matrices=False)
    comps = vh[:2]
    scores = (z - mean) @ comps.T
    scale = scores.std(0)
    explained = (s_vals[:2] ** 2 / (s_vals ** 2).sum())
    return {"mean": mean.float(), "components": comps.float(), "scale": scale.float(), "explained": explained.float()}


@torch.no_grad()
def fit_takeoff_health(model: Dynaformer, ctx_ds: DischargeSet, ridge: float = 1e-8) -> float:
    """Fit ``model.takeoff`` (closed-form ridge least squares, float64) to :func:`takeoff_targets`
    on the noise-free take-off windows of ``ctx_ds`` (cells valid over the whole window).

    :return: RMS residual of the fit (normalised units).
    """
    est = model.takeoff
    w = est.window
    ok = np.flatnonzero(ctx_ds.valid[:, :w].all(1))
    dev = est.mean.device
    x = torch.cat([est.features(torch.as_tensor(ctx_ds.current_a[ok[s:s + 8192], :w], device=dev),
                                torch.as_tensor(ctx_ds.voltage_v[ok[s:s + 8192], :w], device=dev))
                   for s in range(0, ok.size, 8192)])
    y = takeoff_targets(ctx_ds.r0[ok], ctx_ds.q_max[ok], model.cfg).to(dev)
    mean, scale = x.mean(0), x.std(0) + 1e-12
    x = (x - mean) / scale
    bias = y.mean(0)
    gram = x.T @ x + ridge * x.shape[0] * torch.eye(x.shape[1], dtype=torch.float64, device=dev)
    weight = torch.linalg.solve(gram, x.T @ (y - bias))
    est.mean.copy_(mean)
    est.scale.copy_(scale)
    est.weight.copy_(weight)
    est.bias.copy_(bias)
    return float(((x @ weight + bias - y) ** 2).mean().sqrt())


def pretrain_encoder(model: Dynaformer, ctx_ds: DischargeSet, cfg: TrainConfig, rng: np.random.Generator,
                     device) -> float:
    """Stage 1: fit the health head on the encoder (its 2-D output) to :func:`health_targets` on short contexts.

    :return: the final latent MSE (EMA, normalised units).
    """
    params = [p for name, p in model.named_parameters() if name.split(".")[0] in ENCODER_PARTS]
    opt = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(s, cfg.encoder_steps) / cfg.encoder_steps)))
    ema = None
    for _ in tqdm(range(cfg.encoder_steps), desc="encoder", unit="step", mininterval=5.0):
        cidx = rng.integers(0, len(ctx_ds), cfg.context_batch)
        xi, xv, xm = noisy_context(ctx_ds, cidx, rng, max_s=CONTEXT_BATCH_MAX_S)
        z = model.encode(_tensor(xi, device), _tensor(xv, device), _tensor(xm, device, torch.bool))
        loss = ((model.health_head(z) - _tensor(health_targets(ctx_ds, cidx), device)) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        lv = float(loss.detach())
        ema = lv if ema is None else 0.98 * ema + 0.02 * lv
    return float(ema or 0.0)


CHECKPOINT_KEYS = ("model", "opt", "sched", "step", "rng")
"""Entries of a training checkpoint (plus ``train_s``, s): model, optimizer and scheduler state dicts,
optimizer steps done, the numpy generator's state (a dict of strings and ints)."""
_RESUME_HINT = "delete it or start over (resume=False, CLI --no-resume)"


def load_checkpoint(path: str | Path, device: torch.device | str = "cpu") -> dict:
    """A training checkpoint written by :func:`train`, read with :func:`uam_studio.tensor_files.load_tensors`
    (``torch.load(weights_only=True)``): only tensors, numbers, strings, lists, tuples and dicts are
    rebuilt; a file holding anything else is refused before any object in it is built.

    :raises InputError: (field ``checkpoint``) a file that does not load that way, or is not a checkpoint
    """
    try:
        ck = load_tensors(path, map_location=device)
    except TensorFileError as err:
        raise InputError("checkpoint", f"{path}: not a readable training checkpoint ({err}); {_RESUME_HINT}") \
            from None
    ok = (isinstance(ck, dict) and all(k in ck for k in CHECKPOINT_KEYS)
          and all(isinstance(ck[k], dict) for k in ("model", "opt", "sched", "rng"))
          and isinstance(ck["step"], int) and not isinstance(ck["step"], bool) and ck["step"] >= 0
          and isinstance(ck.get("train_s", 0.0), (int, float)))
    if not ok:
        raise InputError("checkpoint", f"{path}: not a training checkpoint (expected entries "
                                       f"{', '.join(CHECKPOINT_KEYS)}); {_RESUME_HINT}")
    return ck


def _resume(path: Path, ck: dict, model: Dynaformer, opt: torch.optim.Optimizer,
            sched: torch.optim.lr_scheduler.LRScheduler, rng: np.random.Generator) -> None:
    """Put a checkpoint's states into the run's model, optimizer, scheduler and generator.

    :raises InputError: (field ``checkpoint``) states that do not fit this run (other model config)
    """
    try:
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["opt"])
        if set(ck["sched"]) != set(sched.state_dict()) or any(f is not None for f in ck["sched"]["lr_lambdas"]):
            raise ValueError("scheduler state has other entries")
        sched.load_state_dict(ck["sched"])
        rng.bit_generator.state = ck["rng"]
    except Exception as exc:
        msg = " ".join(str(exc).split())[:100]
        raise InputError("checkpoint", f"{path}: does not fit this training run ({type(exc).__name__}: {msg}); "
                                       f"{_RESUME_HINT}") from None


def read_init(path: str, model_cfg: DynaformerConfig) -> dict:
    """The state dict to start from: the weights file ``path`` (read without unpickling), whose
    architecture must be ``model_cfg``'s.

    :raises InputError: (field ``init``) a file that does not load, or of another architecture.
    """
    from .artifact import WeightsError, load_artifact

    try:
        init, _, _ = load_artifact(path)
    except WeightsError as err:
        raise InputError("init", str(err)) from None
    arch = ("d_model", "n_heads", "enc_layers", "dec_layers", "ff_dim", "chunk", "latent_dim", "memory_tokens",
            "health", "health_window")
    other = [k for k in arch if getattr(init.cfg, k) != getattr(model_cfg, k)]
    if other:
        raise InputError("init", f"{path}: another architecture ({', '.join(other)} differ)")
    return init.state_dict()


def train(cfg: TrainConfig, out_dir, resume: bool = True, model_cfg: DynaformerConfig | None = None,
          callback=None) -> Path:
    """Train from scratch (or resume from ``out_dir/checkpoint.pt``, see :func:`load_checkpoint`); write
    ``out_dir/dynaformer.pt``.

    :param cfg: training settings.
    :param out_dir: run folder (never the bundled ``pretrained/`` folder).
    :param callback: optional ``f(step, loss)``.
    :return: path of the exported weights.
    :raises InputError: (field ``checkpoint``) a checkpoint that is unreadable, unsafe or from another run.
    """
    model_cfg = model_cfg or DynaformerConfig.for_cell(cfg.cell)
    if model_cfg.cell != cfg.cell:
        raise InputError("cell", f"the model config is for {model_cfg.cell!r}, the training run for {cfg.cell!r}")
    out = Path(out_dir)
    resuming = resume and (out / "checkpoint.pt").exists()
    init_state = read_init(cfg.init, model_cfg) if cfg.init is not None and not resuming else None  # fail fast
    out.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(out)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    device = pick_device(cfg.device)
    ckpt_path = out / "checkpoint.pt"
    ck = load_checkpoint(ckpt_path, device) if resume and ckpt_path.exists() else None  # before the data: fail fast
    torch.manual_seed(cfg.seed)
    t_start = time.perf_counter()
    tag = "" if cfg.cell == "nasa18650" else f"{cfg.cell}_"
    ds = _cached_dataset(out / f"train_data_{tag}seed{cfg.seed}_n{cfg.n_train}.npz", cfg.n_train, cfg.seed,
                         cfg.max_len, cfg.cell)
    ctx_ds = (_cached_dataset(out / f"context_data_{tag}seed{cfg.seed}_n{cfg.n_context}.npz", cfg.n_context,
                              cfg.seed + 7919, CONTEXT_SET_LEN, cfg.cell) if cfg.n_context else None)
    t_data = time.perf_counter() - t_start
    model = Dynaformer(model_cfg).to(device)
    if init_state is not None:
        model.load_state_dict(init_state)
    decoder_params = [p for name, p in model.named_parameters() if name.split(".")[0] not in ENCODER_PARTS]
    opt = torch.optim.AdamW(decoder_params, lr=cfg.lr, weight_decay=1e-4)
    warm = 300
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: (min(1.0, (s + 1) / warm)
                        * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(s, cfg.steps) / cfg.steps)))))
    step, elapsed_before = 0, 0.0
    rng = np.random.default_rng(cfg.seed + 1)
    if ck is not None:
        _resume(ckpt_path, ck, model, opt, sched, rng)
        step, elapsed_before = ck["step"], float(ck.get("train_s", 0.0))
    sampler = BucketSampler(ds.valid.sum(1), cfg.batch, rng)
    model.train()
    t0 = time.perf_counter()
    encoder_mse = None
    takeoff = model_cfg.health == "takeoff"
    if takeoff and step == 0:
        if ctx_ds is None:
            raise ValueError("the take-off health estimator needs n_context > 0 cells to fit on")
        encoder_mse = fit_takeoff_health(model, ctx_ds, cfg.takeoff_ridge)
    elif step == 0 and ctx_ds is not None and cfg.encoder_steps > 0:
        encoder_mse = pretrain_encoder(model, ctx_ds, cfg, rng, device)
    bar = tqdm(total=cfg.steps, initial=step, desc="dynaformer", unit="step", mininterval=5.0)
    ema = None
    while step < cfg.steps:
        ci, cv, cm, cur, volt, w = make_batch(ds, sampler(), rng, model_cfg.chunk, device)
        with torch.no_grad():  # take-off health: from the discharge's own noise-free first window
            latent = model.encode(cur, volt) if takeoff else model.encode(ci, cv, cm)
        pred = model.decode(latent, cur)
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
            "device": str(device), "torch_threads": torch.get_num_threads(),
            "final_rmse_mv_ema": 1000 * math.sqrt(ema or 0), "encoder_stage_health_mse": encoder_mse}
    weights = out / "dynaformer.pt"
    save_artifact(weights, model.cpu(), pca, meta, sidecars={out / "train_meta.json": json.dumps(meta, indent=2)})
    return weights
