"""The Dynaformer network (Biggio et al. 2023), re-designed small for flight profiles on a CPU.

* Health estimator, two kinds (``DynaformerConfig.health``):

  - ``"takeoff"`` (the default): :class:`TakeoffHealth`, a quadratic
    regression on the first ``health_window`` s of the context (the take-off from full
    charge), fitted in closed form to (R0, 6500 C / q_max). Its 2-D output is both the
    health embedding and the decoder's latent. Unlike the transformer encoder, whose
    q_max estimate saturated at the edges of the training range, it extrapolates (median
    q_max error +48 / +18 C at 4000-5000 / 8000-9000 C on noise-free flights), but it is
    fragile to sensor noise (benchmarks/RESULTS.md, "Dynaformer health from noisy sensors").
  - ``"transformer"``:

* Encoder (``"transformer"`` only): the observed context (20 s by default, up to ``max_context`` samples) is
  cut into patches of ``patch`` samples (the paper's 20 s context is one patch);
  each patch token sees its currents, its voltages, their change since the first
  observed sample and its start time. A ``torch.nn.TransformerEncoder`` over the
  patch tokens is mean-pooled into a small **health latent** (``latent_dim``), the
  bottleneck through which all health information must pass to the decoder. A
  linear **health head** projects it to the 2-D **health embedding**; in training
  only, the embedding is supervised to be (R0, q_max) normalised to [-1, 1] and
  [-0.5, 0.5] (see :mod:`uam_studio.dynaformer.train`), so its principal components
  (PCA fitted on training data), the paper's PC1 and PC2, follow R0 and q_max.
  Inference never sees q_max or R0.
* Decoder: the planned current profile is cut into chunks of ``chunk`` samples,
  one query token per chunk. Each token sees its currents, the charge drawn before
  it and its start time (sinusoidal), and is shifted by the health latent. A
  causal ``torch.nn.TransformerDecoder`` cross-attends to latent memory tokens and
  outputs ``chunk`` voltages per token: voltage on the profile's own time grid.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from ..flight import TAKEOFF_CONTEXT_S
from .cells import NASA_TRAINING, dynaformer_cell

V_CENTER, V_SCALE = 3.6, 0.5  # V: voltage normalisation
Q_SCALE = 8000.0  # C: cumulative charge normalisation
T_SCALE = 10000.0  # s


@dataclass(frozen=True)
class DynaformerConfig:
    d_model: int = 64
    n_heads: int = 4
    enc_layers: int = 2
    dec_layers: int = 3
    ff_dim: int = 128
    chunk: int = 64  # samples (s on the 1 s grid) per decoder token
    patch: int = 20  # context samples per encoder token
    latent_dim: int = 8
    memory_tokens: int = 4
    max_context: int = 1024  # samples; longer contexts are strided down to this
    health: str = "takeoff"  # "takeoff" (TakeoffHealth) or "transformer" (the patch encoder)
    health_window: int = TAKEOFF_CONTEXT_S  # samples (s) of the take-off that TakeoffHealth reads
    # The cell type the weights are trained for (uam_studio.dynaformer.cells) and its scales: current
    # (A), and the take-off latent's R0 centre and half-width (ohm) and q_max reference (C) and scale.
    cell: str = NASA_TRAINING.key
    i_scale: float = NASA_TRAINING.i_scale
    r0_mid: float = NASA_TRAINING.r0_mid
    r0_half: float = NASA_TRAINING.r0_half
    u_ref_c: float = NASA_TRAINING.u_ref_c
    u_scale: float = 0.23

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def for_cell(cls, cell: str, **fields) -> DynaformerConfig:
        """The default architecture with the scales of the cell type ``cell``
        (:mod:`uam_studio.dynaformer.cells`); ``fields`` override the rest.

        :raises InputError: (field ``cell``) an unknown type.
        """
        kind = dynaformer_cell(cell)
        return cls(cell=kind.key, i_scale=kind.i_scale, r0_mid=kind.r0_mid, r0_half=kind.r0_half,
                   u_ref_c=kind.u_ref_c, **fields)


def sinusoidal(pos: torch.Tensor, dim: int, max_period: float = 20000.0) -> torch.Tensor:
    """Sinusoidal embedding of positions (any real units), shape [..., dim]."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=pos.device, dtype=torch.float32) / half)
    ang = pos.float().unsqueeze(-1) * freqs
    return torch.cat([torch.sin(ang), torch.cos(ang)], dim=-1)


# The NASA cell's latent scales (the config's defaults): R0's training centre and half-width (ohm);
# health u = (6500 C / q_max - 1) / 0.23, about [-1, 1] in the paper's range.
R0_MID, R0_HALF = DynaformerConfig.r0_mid, DynaformerConfig.r0_half
TAKEOFF_POINTS = 20  # samples of the window that the features use


def takeoff_targets(r0_ohm, q_max_c, cfg: DynaformerConfig | None = None):
    """TakeoffHealth's regression targets [..., 2]: R0 (ohm) and u_ref / q_max (q_max in C), each scaled
    to about [-1, 1] over the training box by ``cfg``'s scales (default: the NASA cell's, 6500 C)."""
    cfg = cfg or DynaformerConfig()
    return torch.stack([(torch.as_tensor(r0_ohm, dtype=torch.float64) - cfg.r0_mid) / cfg.r0_half,
                        (cfg.u_ref_c / torch.as_tensor(q_max_c, dtype=torch.float64) - 1.0) / cfg.u_scale], -1)


def takeoff_to_health(h: torch.Tensor, cfg: DynaformerConfig | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """(R0 in ohm, q_max in C) from TakeoffHealth's output [..., 2] (``cfg``'s scales)."""
    cfg = cfg or DynaformerConfig()
    return h[..., 0] * cfg.r0_half + cfg.r0_mid, cfg.u_ref_c / (h[..., 1] * cfg.u_scale + 1.0)


class TakeoffHealth(nn.Module):
    """Health (R0, 1/q_max) from the take-off: a quadratic regression on the first ``window`` samples.

    Features (float64): the voltage change since the first sample (x10 and divided by the mean
    current), the first voltage, every 4th current, log mean current, and all their pairwise
    products. The weights are buffers fitted in closed form (:func:`uam_studio.dynaformer.train.fit_takeoff_health`).
    The output is clamped to R0 in about [-0.09, 0.56] ohm and q_max in [2700, 16000] C.
    """

    points: torch.Tensor  # buffers (register_buffer)
    iu: torch.Tensor
    mean: torch.Tensor
    scale: torch.Tensor
    weight: torch.Tensor
    bias: torch.Tensor

    def __init__(self, window: int = 20) -> None:
        super().__init__()
        self.window = int(window)
        self.register_buffer("points", torch.linspace(0, window - 1, TAKEOFF_POINTS).round().long())
        n_base = 2 * (TAKEOFF_POINTS - 1) + 1 + len(range(0, TAKEOFF_POINTS, 4)) + 1
        n_feat = n_base + n_base * (n_base + 1) // 2
        self.register_buffer("iu", torch.triu_indices(n_base, n_base))
        self.register_buffer("mean", torch.zeros(n_feat, dtype=torch.float64))
        self.register_buffer("scale", torch.ones(n_feat, dtype=torch.float64))
        self.register_buffer("weight", torch.zeros(n_feat, 2, dtype=torch.float64))
        self.register_buffer("bias", torch.zeros(2, dtype=torch.float64))

    def features(self, ctx_i: torch.Tensor, ctx_v: torch.Tensor) -> torch.Tensor:
        """Raw features [B, F] (float64) from context current (A) and voltage (V), [B, >= window]."""
        if ctx_i.shape[-1] < self.window:
            raise ValueError(f"the take-off health estimate needs {self.window} samples, got {ctx_i.shape[-1]}")
        i = ctx_i[:, self.points].double()
        v = ctx_v[:, self.points].double()
        i_mean = i.mean(1, keepdim=True).clamp_min(0.05)
        dv = v[:, 1:] - v[:, :1]
        base = torch.cat([dv * 10.0, dv / i_mean, (v[:, :1] - 3.6) / 0.5, i[:, ::4] / 3.0, torch.log(i_mean)], 1)
        prod = base.unsqueeze(2) * base.unsqueeze(1)
        return torch.cat([base, prod[:, self.iu[0], self.iu[1]]], 1)

    def forward(self, ctx_i: torch.Tensor, ctx_v: torch.Tensor) -> torch.Tensor:
        x = (self.features(ctx_i, ctx_v) - self.mean) / self.scale
        h = x @ self.weight + self.bias
        h = torch.stack([h[:, 0].clamp(-1.5, 1.5), h[:, 1].clamp(-2.5, 4.0)], 1)
        return torch.nan_to_num(h).float()


class _HealthScale(nn.Module):
    """Health embedding from TakeoffHealth's (R0, u): u at half scale, so that PC1 follows R0
    and PC2 q_max (as in the transformer's supervised embedding). Not used by the decoder."""

    gain: torch.Tensor  # buffer (register_buffer)

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("gain", torch.tensor([1.0, 0.5]), persistent=False)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return h * self.gain


class Dynaformer(nn.Module):
    health_head: nn.Module  # _HealthScale (take-off health) or nn.Linear (transformer)

    def __init__(self, cfg: DynaformerConfig | None = None) -> None:
        super().__init__()
        cfg = cfg or DynaformerConfig()
        dynaformer_cell(cfg.cell)  # an unknown cell type is refused here (InputError)
        if cfg.health not in ("takeoff", "transformer"):
            raise ValueError(f"health must be 'takeoff' or 'transformer', got {cfg.health!r}")
        self.cfg = cfg
        d = cfg.d_model
        if cfg.health == "takeoff":
            self.latent_dim = 2
            self.takeoff = TakeoffHealth(cfg.health_window)
            self.health_head = _HealthScale()  # the estimate, R0 at twice q's spread, is the health embedding
        else:
            self.latent_dim = cfg.latent_dim
            n_in = 5 * cfg.patch + 1
            self.enc_in = nn.Sequential(nn.Linear(n_in, 4 * d), nn.GELU(), nn.Linear(4 * d, 4 * d), nn.GELU(),
                                        nn.Linear(4 * d, d))
            enc_layer = nn.TransformerEncoderLayer(d, cfg.n_heads, cfg.ff_dim, dropout=0.0, batch_first=True,
                                                   norm_first=True)
            self.encoder = nn.TransformerEncoder(enc_layer, cfg.enc_layers, enable_nested_tensor=False)
            self.to_latent = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, d), nn.GELU(), nn.Linear(d, cfg.latent_dim))
            self.health_head = nn.Linear(cfg.latent_dim, 2)  # latent -> 2-D health embedding
        self.latent_to_memory = nn.Linear(self.latent_dim, d * cfg.memory_tokens)
        self.latent_to_query = nn.Linear(self.latent_dim, d)
        self.dec_in = nn.Linear(cfg.chunk + 3, d)
        dec_layer = nn.TransformerDecoderLayer(d, cfg.n_heads, cfg.ff_dim, dropout=0.0, batch_first=True,
                                               norm_first=True)
        self.decoder = nn.TransformerDecoder(dec_layer, cfg.dec_layers)
        self.head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, cfg.chunk))

    # -- encoder ---------------------------------------------------------------------------
    def encode(self, ctx_i: torch.Tensor, ctx_v: torch.Tensor, ctx_mask: torch.Tensor | None = None) -> torch.Tensor:
        """Health latent [B, latent_dim] from context current (A) and voltage (V), [B, L].

        ctx_mask: [B, L] True where the sample is real (contexts of different lengths); the
        take-off estimator reads the first ``health_window`` samples and ignores it.
        """
        if self.cfg.health == "takeoff":
            return self.takeoff(ctx_i, ctx_v)
        b, n = ctx_i.shape
        p = self.cfg.patch
        if ctx_mask is None:
            ctx_mask = torch.ones_like(ctx_i, dtype=torch.bool)
        n_tok = max(1, -(-n // p))
        pad = n_tok * p - n
        m = nn.functional.pad(ctx_mask, (0, pad), value=False).float()
        i = nn.functional.pad(ctx_i, (0, pad)) * m
        v = nn.functional.pad(ctx_v, (0, pad))
        v0 = ctx_v[:, :1]
        dv = (v - v0) * m
        v = torch.where(m > 0, v, v0)
        step = torch.diff(v, dim=1, prepend=v[:, :1]) * m
        start_s = torch.arange(n_tok, device=ctx_i.device, dtype=torch.float32) * p
        feats = torch.cat([(i / self.cfg.i_scale).view(b, n_tok, p), ((v - V_CENTER) / V_SCALE).view(b, n_tok, p),
                           (dv * 10.0).view(b, n_tok, p),
                           (step * 100.0).view(b, n_tok, p), m.view(b, n_tok, p),
                           (start_s / 600.0).expand(b, n_tok).unsqueeze(-1)], dim=-1)
        tok_mask = m.view(b, n_tok, p).any(-1)
        h = self.encoder(self.enc_in(feats), src_key_padding_mask=~tok_mask)
        w = tok_mask.unsqueeze(-1).float()
        pooled = (h * w).sum(1) / w.sum(1).clamp_min(1.0)
        return self.to_latent(pooled)

    # -- decoder ---------------------------------------------------------------------------
    def decode(self, latent: torch.Tensor, current: torch.Tensor) -> torch.Tensor:
        """Voltage (V) [B, T] for currents (A) [B, T] on the 1 s grid, T a multiple of ``chunk``."""
        cfg = self.cfg
        b, t = current.shape
        n_tok = t // cfg.chunk
        chunks = current.view(b, n_tok, cfg.chunk)
        charge_before = torch.cumsum(chunks.sum(-1), dim=1) - chunks.sum(-1)  # C on the 1 s grid
        start_s = torch.arange(n_tok, device=current.device, dtype=torch.float32) * cfg.chunk
        feats = torch.cat([chunks / cfg.i_scale, (charge_before / Q_SCALE).unsqueeze(-1),
                           (start_s / T_SCALE).expand(b, n_tok).unsqueeze(-1),
                           chunks.mean(-1, keepdim=True) / cfg.i_scale], dim=-1)
        q = self.dec_in(feats) + sinusoidal(start_s, cfg.d_model).unsqueeze(0) + self.latent_to_query(latent)[:, None]
        memory = self.latent_to_memory(latent).view(b, cfg.memory_tokens, cfg.d_model)
        causal = nn.Transformer.generate_square_subsequent_mask(n_tok, device=current.device)
        h = self.decoder(q, memory, tgt_mask=causal, tgt_is_causal=True)
        return (self.head(h) * V_SCALE + V_CENTER).reshape(b, t)

    def forward(self, ctx_i, ctx_v, current, ctx_mask=None) -> torch.Tensor:
        return self.decode(self.encode(ctx_i, ctx_v, ctx_mask), current)
