"""The Dynaformer network (Biggio et al. 2023), re-designed small for flight profiles on a CPU.

* Encoder: the observed context (20 s by default, up to ``max_context`` samples) is
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

V_CENTER, V_SCALE = 3.6, 0.5  # V: voltage normalisation
I_SCALE = 3.0  # A
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

    def to_dict(self) -> dict:
        return asdict(self)


def sinusoidal(pos: torch.Tensor, dim: int, max_period: float = 20000.0) -> torch.Tensor:
    """Sinusoidal embedding of positions (any real units), shape [..., dim]."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=pos.device, dtype=torch.float32) / half)
    ang = pos.float().unsqueeze(-1) * freqs
    return torch.cat([torch.sin(ang), torch.cos(ang)], dim=-1)


class Dynaformer(nn.Module):
    def __init__(self, cfg: DynaformerConfig | None = None) -> None:
        super().__init__()
        cfg = cfg or DynaformerConfig()
        self.cfg = cfg
        d = cfg.d_model
        n_in = 5 * cfg.patch + 1
        self.enc_in = nn.Sequential(nn.Linear(n_in, 4 * d), nn.GELU(), nn.Linear(4 * d, 4 * d), nn.GELU(),
                                    nn.Linear(4 * d, d))
        enc_layer = nn.TransformerEncoderLayer(d, cfg.n_heads, cfg.ff_dim, dropout=0.0, batch_first=True,
                                               norm_first=True)
        self.encoder = nn.TransformerEncoder(enc_layer, cfg.enc_layers, enable_nested_tensor=False)
        self.to_latent = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, d), nn.GELU(), nn.Linear(d, cfg.latent_dim))
        self.health_head = nn.Linear(cfg.latent_dim, 2)  # latent -> 2-D health embedding
        self.latent_to_memory = nn.Linear(cfg.latent_dim, d * cfg.memory_tokens)
        self.latent_to_query = nn.Linear(cfg.latent_dim, d)
        self.dec_in = nn.Linear(cfg.chunk + 3, d)
        dec_layer = nn.TransformerDecoderLayer(d, cfg.n_heads, cfg.ff_dim, dropout=0.0, batch_first=True,
                                               norm_first=True)
        self.decoder = nn.TransformerDecoder(dec_layer, cfg.dec_layers)
        self.head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, cfg.chunk))

    # -- encoder ---------------------------------------------------------------------------
    def encode(self, ctx_i: torch.Tensor, ctx_v: torch.Tensor, ctx_mask: torch.Tensor | None = None) -> torch.Tensor:
        """Health latent [B, latent_dim] from context current (A) and voltage (V), [B, L].

        ctx_mask: [B, L] True where the sample is real (contexts of different lengths).
        """
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
        feats = torch.cat([(i / I_SCALE).view(b, n_tok, p), ((v - V_CENTER) / V_SCALE).view(b, n_tok, p),
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
        feats = torch.cat([chunks / I_SCALE, (charge_before / Q_SCALE).unsqueeze(-1),
                           (start_s / T_SCALE).expand(b, n_tok).unsqueeze(-1),
                           chunks.mean(-1, keepdim=True) / I_SCALE], dim=-1)
        q = self.dec_in(feats) + sinusoidal(start_s, cfg.d_model).unsqueeze(0) + self.latent_to_query(latent)[:, None]
        memory = self.latent_to_memory(latent).view(b, cfg.memory_tokens, cfg.d_model)
        causal = nn.Transformer.generate_square_subsequent_mask(n_tok, device=current.device)
        h = self.decoder(q, memory, tgt_mask=causal, tgt_is_causal=True)
        return (self.head(h) * V_SCALE + V_CENTER).reshape(b, t)

    def forward(self, ctx_i, ctx_v, current, ctx_mask=None) -> torch.Tensor:
        return self.decode(self.encode(ctx_i, ctx_v, ctx_mask), current)
