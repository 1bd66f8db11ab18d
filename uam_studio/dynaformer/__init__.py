"""Dynaformer: a transformer that infers battery health from a short context and predicts voltage."""
