"""The attention planner's network: a Transformer encoder over the mission's tokens and a pointer
decoder that scores every candidate of a decision (Kool, van Hoof and Welling, ICLR 2019, in spirit:
no positional encoding, so the encoder is permutation-invariant and one network serves any number of
destinations).

``encode(tokens, pad)`` -> per-token embeddings ``h`` [B, T, d] and the graph embedding (mean over
real tokens) [B, d], once per mission. ``decide(h, graph, at, context, candidates, mask)`` -> logits
[B, T] of the next token (``-inf`` where masked), once per decision: the context vector is an MLP of
the current token's embedding, the graph embedding and the decision's context features; each
candidate's logit is an MLP of its embedding, the context vector and its candidate features.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from uam_studio.planning.agents.attention.features import CANDIDATE_FEATURES, CONTEXT_FEATURES, TOKEN_FEATURES

__all__ = ["AttentionConfig", "AttentionPolicy"]


@dataclass(frozen=True)
class AttentionConfig:
    """Network size: ``d_model`` embedding width, ``heads`` attention heads, ``layers`` encoder layers,
    ``ff`` feed-forward width."""

    d_model: int = 64
    heads: int = 4
    layers: int = 3
    ff: int = 128

    def to_dict(self) -> dict[str, int]:
        return asdict(self)


class AttentionPolicy(nn.Module):
    """Encoder-decoder policy over the tokens of
    :func:`~uam_studio.planning.agents.attention.features.mission_tokens`."""

    def __init__(self, config: AttentionConfig | None = None) -> None:
        super().__init__()
        c = config or AttentionConfig()
        self.config = c
        d = c.d_model
        self.embed = nn.Linear(TOKEN_FEATURES, d)
        layer = nn.TransformerEncoderLayer(d, c.heads, c.ff, dropout=0.0, batch_first=True)
        self.encoder = nn.TransformerEncoder(layer, c.layers, enable_nested_tensor=False)
        self.context = nn.Sequential(nn.Linear(2 * d + CONTEXT_FEATURES, d), nn.ReLU(), nn.Linear(d, d))
        self.score = nn.Sequential(nn.Linear(2 * d + CANDIDATE_FEATURES, d), nn.ReLU(), nn.Linear(d, d), nn.ReLU(),
                                   nn.Linear(d, 1))

    def encode(self, tokens: torch.Tensor, pad: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``tokens`` [B, T, TOKEN_FEATURES], ``pad`` [B, T] (True = padding) -> (h [B, T, d], graph [B, d])."""
        h = self.encoder(self.embed(tokens), src_key_padding_mask=pad)
        if pad is None:
            return h, h.mean(dim=1)
        real = (~pad).unsqueeze(-1).to(h.dtype)
        return h, (h * real).sum(dim=1) / real.sum(dim=1).clamp(min=1.0)

    def decide(self, h: torch.Tensor, graph: torch.Tensor, at: torch.Tensor, context: torch.Tensor,
               candidates: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Logits [B, T] of the next token; ``at`` [B] current token, ``context`` [B, CONTEXT_FEATURES],
        ``candidates`` [B, T, CANDIDATE_FEATURES], ``mask`` [B, T] (True = allowed)."""
        h_at = h[torch.arange(h.shape[0]), at]
        ctx = self.context(torch.cat([h_at, graph, context], dim=-1))
        t = h.shape[1]
        logits = self.score(torch.cat([h, ctx.unsqueeze(1).expand(-1, t, -1), candidates], dim=-1)).squeeze(-1)
        return logits.masked_fill(~mask, float("-inf"))
