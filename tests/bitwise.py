"""Bit-for-bit comparison of saved models, for the tests of exact resume."""

import torch as th
from stable_baselines3.common.save_util import load_from_zip_file


def same(a, b) -> bool:
    """Whether two nested records of tensors, arrays and numbers are equal, bit for bit."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[key], b[key]) for key in a)
    if isinstance(a, list | tuple):
        return isinstance(b, list | tuple) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, th.Tensor):
        return isinstance(b, th.Tensor) and a.dtype == b.dtype and a.shape == b.shape and bool((a == b).all())
    return a == b


def saved_weights(path) -> dict:
    """:return: a saved model's weights, target networks, Adam's moments and steps"""
    return load_from_zip_file(path, device="cpu")[1]
