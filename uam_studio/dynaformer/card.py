"""Write a Dynaformer model card (Markdown) from training metadata and measured metrics."""

from __future__ import annotations

import json
import platform

import torch

from .evaluate import format_report


def model_card(meta: dict, metrics: dict, command: str, n_params: int, size_bytes: int) -> str:
    tc = meta.get("train_config", {})
    cpu = platform.processor() or platform.machine()
    return f"""# Dynaformer model card (`pretrained/dynaformer.pt`)

**What**: a small transformer decoder that reads the first 20 s of observed per-cell
current and voltage at take-off, infers the battery's health with no access to q_max or
R0, and predicts the voltage for a whole planned current profile on a 1 s grid.
Architecture: `uam_studio/dynaformer/model.py`, {n_params:,} parameters, {size_bytes / 1e6:.2f} MB file.
- Health: `TakeoffHealth`, a quadratic regression on the first {meta.get('health_window', 20)} s of the
  context (voltage changes, first voltage, currents and all their pairwise products, 1080
  features), fitted in closed form (ridge {tc.get('takeoff_ridge')}) to R0 and 6500 C / q_max. Its 2-D output
  is the health embedding (PCA with 2 components, fitted on the training contexts and stored
  in the same file) and the latent the decoder reads. A longer context is accepted; only its
  first {meta.get('health_window', 20)} s are read.
- Decoder: a causal torch.nn Transformer decoder over 64-sample chunks of the profile,
  conditioned on the health through a linear query shift and linear memory tokens.
- Why not the transformer encoder of sessions 5-7 (still loadable, `health="transformer"`):
  its q_max estimate saturated at the edges of the training range (-1045 C at
  8000-9000 C), so extrapolation missed the goal; the quadratic estimate is within a median
  of +48 / +18 C there on noise-free flights. Its price is noise: see Limits.

**Reproduce** (from the repository root; writes to `runs/`, never to `pretrained/`):

    {command}
    cp runs/dynaformer/dynaformer.pt pretrained/dynaformer.pt

**Data**: {tc.get('n_train')} synthetic discharges from our own flight and battery
models (`uam_studio/dynaformer/data.py`, seed {tc.get('seed')}): 70% random 1-6 leg
missions (distance, altitude 500-3000 m, wind +/-39 kt, optional dwell), 30%
constant and piecewise-constant loads of 0.05-3 A. Health: q_max ~ U[5000, 8000] C,
r0 ~ U[0.017, 0.45] ohm. Targets are simulated down to 2.5 V, at most
{tc.get('max_len')} s. Plus {tc.get('n_context')} cheap short discharges (600 s, seed + 7919)
whose noise-free first 20 s fit the health estimator.

**Training**: the closed-form health fit, then {tc.get('steps')} AdamW steps of the decoder,
batch {tc.get('batch')}, lr {tc.get('lr')} (warm-up and cosine decay), on {meta.get('device')} with
{meta.get('torch_threads')} torch threads ({cpu}). The decoder reads the health estimate of each
discharge's own noise-free take-off and learns the voltage: MSE with 4x weight for true
voltages in (2.8, 3.3) V. The q_max/R0 targets are training-only (inference never sees
them). RMS residual of the health fit: {meta.get('encoder_stage_health_mse')} (normalised units).
Wall time: {meta.get('data_seconds')} s of data loading or generation plus
{meta.get('train_seconds')} s of training.

**Measured metrics** (`uam-studio evaluate dynaformer`, held-out seeds disjoint from
training; EOD at 3.0 V; RTE = |t_pred - t_true| / t_true):

```
{format_report(metrics)}
```

**Limits**: **sensor noise.** The health estimate is exact to a few coulombs on noise-free
contexts but is thrown off by voltage noise: with 5 mV of noise its q_max is useless and
R0's correlation drops (health table above). The app and the planning environment feed
noise-free physics contexts. It is trained on our synthetic physics, not on measured cells. The
extrapolation band is q_max in [4000, 5000] or [8000, 9000] C, or r0 in
[0.45, 0.5] ohm. Cells with r0 above about 0.38 ohm fall below 3.0 V during the
3 A takeoff, so their flight "EOD" is a few seconds and the RTE there is noisy.
torch {torch.__version__}.

<details><summary>raw metrics</summary>

```json
{json.dumps(metrics, indent=1)}
```
</details>
"""
