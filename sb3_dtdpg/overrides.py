"""Hyperparameter overrides given as text, checked before anything is built.

``sb3-dtdpg train --hyperparams learning_rate:3e-4 batch_size:256`` takes the RL Zoo's ``key:value`` form
(``rl_zoo3``'s ``StoreDict``). The zoo evaluates each value as Python; here a value is a Python literal
(``3e-4``, ``True``, ``[64, 64]``, ``'text'``), ``dict(key=literal, ...)`` (the zoo's ``policy_kwargs`` form) or
a torch module or optimizer class (``nn.Tanh``, ``th.optim.Adam``, as the zoo's files write them), read with
:mod:`ast`, so a command line runs no code.

:func:`check_constructor_kwargs` is the check both the CLI and ``python -m sb3_dtdpg.train`` run on a set of
keyword arguments before the model is built: an unknown name gets a did-you-mean (a typo such as
``learnin_rate`` would otherwise be a ``TypeError`` from deep inside SB3), and a network larger than
:data:`MAX_NETWORK_PARAMETERS` is refused before torch tries to allocate it.
"""

from __future__ import annotations

import ast
import difflib
import inspect
import itertools
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = [
    "MAX_NETWORK_PARAMETERS",
    "HyperparameterError",
    "check_constructor_kwargs",
    "override_text",
    "parse_overrides",
    "parse_value",
]

#: The most weights one hidden-layer stack of ``net_arch`` may have (products of consecutive layer sizes):
#: 20 million, 80 MB of float32 per network, about 1 GB with the actor, critic, their targets and Adam's state.
MAX_NETWORK_PARAMETERS = 20_000_000
#: Names the constructor never sees: the model's own positional arguments.
_NOT_KWARGS = ("self", "policy", "env")


class HyperparameterError(ValueError):
    """A hyperparameter override or file entry that cannot be used (named, with the value)."""


#: Where ``--hyperparams`` finds the classes it may name (the RL Zoo's files write ``nn.ReLU``, ``th.optim.Adam``):
#: each prefix's module and the base class its names must be.
_CLASS_MODULES: dict[str, tuple[str, str]] = {
    prefix: (module, base)
    for prefixes, module, base in (
        (("nn", "th.nn", "torch.nn"), "torch.nn", "Module"),
        (("optim", "th.optim", "torch.optim"), "torch.optim", "Optimizer"),
    )
    for prefix in prefixes
}


def _dotted_name(node: ast.AST) -> str | None:
    """:return: ``"th.nn.ReLU"`` for a chain of attribute names, None for any other expression"""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        owner = _dotted_name(node.value)
        return None if owner is None else f"{owner}.{node.attr}"
    return None


def _torch_class(node: ast.Attribute, text: str) -> type:
    """:return: the torch class an attribute chain names (``nn.Tanh``: ``torch.nn.Tanh``), imported on first use
    :raises HyperparameterError: a name outside :data:`_CLASS_MODULES`, or one its module has no class of"""
    import importlib

    dotted = _dotted_name(node)
    prefix, _, name = (dotted or "").rpartition(".")
    if prefix not in _CLASS_MODULES:
        raise HyperparameterError(
            f"{text!r}: {dotted or ast.unparse(node)!r} is not a literal; the names a value may hold are torch's "
            "module and optimizer classes (e.g. nn.ReLU, th.optim.Adam)"
        )
    module_name, base_name = _CLASS_MODULES[prefix]
    module = importlib.import_module(module_name)
    base = getattr(module, base_name)
    found = getattr(module, name, None)
    if not (isinstance(found, type) and issubclass(found, base)):
        known = [n for n in dir(module) if isinstance(getattr(module, n), type) and issubclass(getattr(module, n), base)]
        raise HyperparameterError(f"{text!r}: {module_name} has no {base_name} class {name!r}{_closest(name, known)}")
    return found


def override_text(value: Any) -> str:
    """
    :param value: an override value as :func:`parse_value` returns it
    :return: its text, which :func:`parse_value` reads back to the same value: ``repr(value)``, with the torch
        classes it holds written as ``nn.Tanh`` / ``th.optim.Adam``
    """
    if isinstance(value, type):  # the names _torch_class reads: the classes torch.nn and torch.optim export
        for module_name, prefix in (("torch.nn", "nn"), ("torch.optim", "th.optim")):
            if getattr(sys.modules.get(module_name), value.__name__, None) is value:
                return f"{prefix}.{value.__name__}"
        return repr(value)
    if isinstance(value, dict):
        return "{" + ", ".join(f"{override_text(key)}: {override_text(item)}" for key, item in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(map(override_text, value)) + "]"
    if isinstance(value, tuple):
        return "(" + ", ".join(map(override_text, value)) + ("," if len(value) == 1 else "") + ")"
    return repr(value)


def _literal(node: ast.AST, text: str) -> Any:
    if isinstance(node, ast.Attribute):  # nn.ReLU, th.optim.Adam: the classes of the zoo's policy_kwargs
        return _torch_class(node, text)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict" and not node.args:
        if any(keyword.arg is None for keyword in node.keywords):
            raise HyperparameterError(f"{text!r}: dict(**...) is not a literal")
        return {keyword.arg: _literal(keyword.value, text) for keyword in node.keywords}
    if isinstance(node, (ast.List, ast.Tuple)):  # e.g. phases: [dict(...), dict(...)]
        items = [_literal(item, text) for item in node.elts]
        return items if isinstance(node, ast.List) else tuple(items)
    if isinstance(node, ast.Dict) and None not in node.keys:
        try:
            return {_literal(key, text): _literal(value, text) for key, value in zip(node.keys, node.values, strict=True)}
        except TypeError:  # an unhashable key
            raise HyperparameterError(f"{text!r}: a dict key must be a number, a string or a tuple") from None
    try:
        return ast.literal_eval(node)
    except ValueError:
        raise HyperparameterError(
            f"{text!r} is not a Python literal (a number, True/False/None, a quoted string, a list, a dict or dict(k=v))"
        ) from None


def parse_value(text: str) -> Any:
    """
    :param text: a value as typed, e.g. ``3e-4``, ``[64, 64]``, ``dict(net_arch=[64, 64])``
    :return: the value; a bare word that is not a literal (``relabel``) is kept as that string
    :raises HyperparameterError: when the text is an expression other than a literal
    """
    try:
        node = ast.parse(text.strip(), mode="eval").body
    except SyntaxError:
        raise HyperparameterError(f"{text!r} is not a Python literal") from None
    if isinstance(node, ast.Name):  # a bare word: the zoo's strings are usually quoted, accept it unquoted too
        return {"True": True, "False": False, "None": None}.get(node.id, node.id)
    return _literal(node, text)


def parse_overrides(items: Iterable[str]) -> dict[str, Any]:
    """
    :param items: ``key:value`` strings (the RL Zoo's ``--hyperparams`` form)
    :return: the overrides, in order (a repeated key keeps its last value)
    :raises HyperparameterError: an item without ``:``, with an empty key or a value that is not a literal
    """
    overrides: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition(":")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise HyperparameterError(f"{item!r}: expected key:value, e.g. learning_rate:3e-4")
        overrides[key] = parse_value(value)
    return overrides


#: The networks of a ``net_arch`` dict, as SB3's off-policy policies read it (``get_actor_critic_arch``)
_NET_ARCH_KEYS = ("pi", "qf")


def _check_net_arch(net_arch: Any, where: str) -> None:
    if isinstance(net_arch, dict) and sorted(net_arch) != sorted(_NET_ARCH_KEYS):
        raise HyperparameterError(
            f"net_arch{where}: a dict gives the actor's and the critics' layers, keys exactly 'pi' and 'qf' (e.g. "
            f"dict(pi=[64, 64], qf=[400, 300])), got the keys {list(net_arch)}"
        )
    if not isinstance(net_arch, dict | list):  # SB3 asserts one or the other (a tuple fails); a dict's values are free
        raise HyperparameterError(f"net_arch{where}: expected a list of layer sizes or a dict of them, got {net_arch!r}")
    stacks = net_arch.values() if isinstance(net_arch, dict) else [net_arch]
    for stack in stacks:
        if not isinstance(stack, Sequence) or isinstance(stack, str):
            raise HyperparameterError(f"net_arch{where}: expected a list of layer sizes, got {net_arch!r}")
        for size in stack:
            if isinstance(size, bool) or not isinstance(size, int) or size < 1:
                raise HyperparameterError(f"net_arch{where}: layer sizes must be positive integers, got {size!r}")
        weights = sum(a * b for a, b in itertools.pairwise(stack)) + sum(stack)
        if weights > MAX_NETWORK_PARAMETERS:
            raise HyperparameterError(
                f"net_arch{where}: {list(stack)} has {weights:.3g} weights in its hidden layers alone, more than the "
                f"{MAX_NETWORK_PARAMETERS:,} allowed (sb3_dtdpg.overrides.MAX_NETWORK_PARAMETERS)"
            )


def _closest(name: str, known: list[str]) -> str:
    """:return: ``"; did you mean ..."`` with the known names closest to an unknown one (empty where none is close)"""
    close = difflib.get_close_matches(name, known, n=3)
    return f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


#: Policy arguments that take a class (a quoted name is a string, not the class: nn.ReLU is written unquoted)
_CLASS_ARGUMENTS = ("activation_fn", "optimizer_class", "features_extractor_class")


def _check_policy_kwargs(algo_class: type, policy_kwargs: Mapping[str, Any], where: str) -> None:
    """:raises HyperparameterError: a name the algorithm's ``MlpPolicy`` does not take (with the closest ones), or a
    string where it takes a class"""
    policy_class = getattr(algo_class, "policy_aliases", {}).get("MlpPolicy")
    if policy_class is not None:
        parameters = inspect.signature(policy_class).parameters
        if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
            known = [name for name in parameters if name not in ("observation_space", "action_space", "lr_schedule")]
            for name in policy_kwargs:
                if name not in known:
                    raise HyperparameterError(
                        f"unknown policy_kwargs key {name!r} for {policy_class.__name__}{where}{_closest(name, known)}"
                    )
    for name in _CLASS_ARGUMENTS:
        if isinstance(policy_kwargs.get(name), str):
            raise HyperparameterError(
                f"policy_kwargs[{name!r}]{where} must be a class (e.g. nn.ReLU, unquoted), got the string "
                f"{policy_kwargs[name]!r}"
            )


def check_constructor_kwargs(
    algo_class: type,
    kwargs: dict[str, Any],
    where: str = "",
    extra: Sequence[str] = (),
    reserved: Mapping[str, str] | None = None,
) -> None:
    """
    Check keyword arguments for ``algo_class(policy, env, **kwargs)`` before it is called.

    :param algo_class: an SB3 algorithm class (``DTDPG``, ``DDPG``, ...)
    :param kwargs: the keyword arguments
    :param where: where they come from, for the message (e.g. ``" in zoo_configs/dtdpg.yml"``)
    :param extra: further names that are valid besides the constructor's (e.g. the zoo's own keys)
    :param reserved: names the caller sets itself, each with the option that sets it (e.g. ``{"seed": "--seed"}``)
    :raises HyperparameterError: an unknown or reserved name (with the closest known ones or the option to use), a
        learning rate that is not a positive finite number (or a schedule), a ``policy_kwargs`` that is not a dict,
        names an argument the algorithm's ``MlpPolicy`` does not take, gives a string for a class or whose
        ``net_arch`` is malformed or too large, a ``device`` torch does not know, or a numeric setting out of
        the range :func:`sb3_dtdpg.common.checks.check_off_policy_settings` allows
    """
    from sb3_dtdpg.common.checks import check_off_policy_settings
    from sb3_dtdpg.common.phases import parse_phases

    parameters = inspect.signature(algo_class).parameters
    known = [name for name in parameters if name not in _NOT_KWARGS and not name.startswith("_")] + list(extra)
    for name in kwargs:
        if name in (reserved or {}):
            raise HyperparameterError(f"{name}{where}: set it with {reserved[name]}, not as a hyperparameter")
        if name not in known:
            hint = _closest(name, known)
            raise HyperparameterError(f"unknown hyperparameter {name!r} for {algo_class.__name__}{where}{hint}")
    rate = kwargs.get("learning_rate")
    if rate is not None and not callable(rate) and not (_is_number(rate) and math.isfinite(rate) and rate > 0):
        raise HyperparameterError(f"learning_rate{where} must be a positive finite number, got {rate!r}")
    policy_kwargs = kwargs.get("policy_kwargs")
    if policy_kwargs is not None and not isinstance(policy_kwargs, Mapping):
        raise HyperparameterError(f"policy_kwargs{where} must be a dict, e.g. dict(net_arch=[64, 64]), got {policy_kwargs!r}")
    if isinstance(policy_kwargs, Mapping):
        _check_policy_kwargs(algo_class, policy_kwargs, where)
    if isinstance(policy_kwargs, Mapping) and "net_arch" in policy_kwargs:
        _check_net_arch(policy_kwargs["net_arch"], where)
    if kwargs.get("device") is not None:
        _check_device(kwargs["device"], where)
    try:
        check_off_policy_settings(f"{algo_class.__name__}{where}", kwargs)
        if kwargs.get("phases") is not None and "phases" in parameters:  # DT-DPG's curriculum
            parse_phases(kwargs["phases"])
    except ValueError as error:
        raise HyperparameterError(f"{error}{where}" if "phases" in str(error) else str(error)) from None
    _check_batch_norm_batch(algo_class, kwargs, where)


def _check_batch_norm_batch(algo_class: type, kwargs: Mapping[str, Any], where: str) -> None:
    """A batch of one with the batch-norm policy (its ``actor_norm`` / ``critic_norm``, ``"batch"`` by default) has no
    variance: refused here, before the model is built (the constructor refuses it once its networks exist)."""
    batch_size = kwargs.get("batch_size")
    policy = getattr(algo_class, "policy_aliases", {}).get("MlpPolicy")
    if batch_size is None or not _is_number(batch_size) or batch_size >= 2 or policy is None:
        return
    norms = inspect.signature(policy).parameters
    policy_kwargs = kwargs.get("policy_kwargs") or {}
    if any(
        name in norms and policy_kwargs.get(name, norms[name].default) == "batch" for name in ("actor_norm", "critic_norm")
    ):
        raise HyperparameterError(
            f"{algo_class.__name__}{where}: batch_size must be at least 2 with batch normalisation (actor_norm or "
            f"critic_norm 'batch'), got {batch_size!r}"
        )


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_device(device: Any, where: str) -> None:
    from stable_baselines3.common.utils import get_device

    try:
        get_device(device)
    except (RuntimeError, TypeError):
        raise HyperparameterError(f"device{where}: torch knows no device {device!r} (e.g. 'cpu', 'cuda', 'auto')") from None
