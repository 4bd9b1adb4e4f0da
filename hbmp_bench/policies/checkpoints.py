"""Checkpoint files: plain state dicts and config dicts, loadable with ``torch.load(weights_only=True)``.

A checkpoint is a dict:

    format               CHECKPOINT_FORMAT
    kind                 "il", "hbmp", "hbmp-s", "flat" or "flat-il" (DAgger on the flat baseline's controls)
    model                {"actor": rsl-rl model config, "critic": ..., "obs_shapes": {group: [dims]},
                          "obs_groups": {"actor": [...], "critic": [...]}, "num_actions": int,
                          "action_space": "discrete" | "box", "env": {env id and options}}
    actor_state_dict     the policy's weights
    critic_state_dict    the value network's weights (PPO; absent for il)
    optimizer_state_dict to resume (DAgger's; absent in PPO checkpoints and the shipped policy files)
    progress             {"episodes", "decisions", "iterations", "wall_s"}
    train                the training options and the command that produced it

Only str, int, float, bool, None, lists and dicts of them, and tensors go in, so the file loads
under ``weights_only=True``. A model config names the classes that build the network
(``class_name``, resolved by rsl-rl): a loaded checkpoint may name only ``NETWORK_CLASSES``, the
package's own network and distributions, so that building a policy never imports or runs a module
the file's author chose (``check_network_classes``). torch is imported by the functions that need it, so that ``KINDS``
(the command line's choices) costs nothing to import.
"""

from __future__ import annotations

import os
import pickle
import re
import tempfile
from typing import Any

from hbmp_bench.errors import UserError

CHECKPOINT_FORMAT = "hbmp_bench.checkpoint.v1"
KINDS = ("il", "hbmp", "hbmp-s", "flat", "flat-il")
PLAIN_TYPES = (str, int, float, bool, type(None))
NETWORK_CLASSES = (
    "hbmp_bench.policies.networks:BehaviorNetwork",
    "hbmp_bench.policies.distributions:CategoricalDistribution",
    "rsl_rl.modules.distribution:GaussianDistribution",
)
"""The only ``class_name`` values a checkpoint's model config may hold: the paper's network, its
categorical output and the Gaussian output of the flat baseline (what :mod:`hbmp_bench.policies.networks`
writes)."""
FORMER_NETWORK_CLASSES = {
    "hbmp_bench.training.models:BehaviorNetwork": "hbmp_bench.policies.networks:BehaviorNetwork",
    "hbmp_bench.training.distributions:CategoricalDistribution":
        "hbmp_bench.policies.distributions:CategoricalDistribution",
}
"""Where the package's network classes lived when the shipped checkpoints were written (under
``training``): a checkpoint naming one of these is read as naming the class it became, so every
checkpoint written before the move loads, and building it never imports the training code."""


def _check_plain(value: Any, where: str) -> None:
    import torch

    if isinstance(value, PLAIN_TYPES) or isinstance(value, torch.Tensor):
        return
    if isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            _check_plain(v, f"{where}[{k}]")
        return
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, (str, int)):
                raise ValueError(f"checkpoint key {where}.{k!r} must be a str or int")
            _check_plain(v, f"{where}.{k}")
        return
    raise ValueError(f"checkpoint entry {where} has type {type(value).__name__}; only plain values and tensors "
                     "are stored so the file loads with weights_only=True")


def save_checkpoint(path: str, checkpoint: dict[str, Any]) -> None:
    """Write ``checkpoint`` atomically (temp file in the same folder, then rename)."""
    checkpoint = {"format": CHECKPOINT_FORMAT, **checkpoint}
    if checkpoint.get("kind") not in KINDS:
        raise ValueError(f"checkpoint kind must be one of {KINDS}, got {checkpoint.get('kind')!r}")
    _check_plain(checkpoint, "checkpoint")
    import torch

    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".ckpt-", suffix=".tmp", dir=folder)
    os.close(fd)
    try:
        torch.save(checkpoint, tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; a checkpoint is an ordinary file
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


class CheckpointError(UserError):
    """A checkpoint file that cannot be used: refused by the weights-only loader, unreadable
    (truncated, not a torch file), or not an hbmp_bench checkpoint of the expected kind."""


def load_checkpoint(path: str, kinds: tuple[str, ...] = KINDS) -> dict[str, Any]:
    """Read a checkpoint with ``weights_only=True``; its kind must be in ``kinds``.

    Raises:
        FileNotFoundError: no file at ``path``.
        CheckpointError: the file is refused, unreadable or of another kind (one line; torch's
            error is the ``__cause__``).
    """
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no checkpoint file {path!r}")
    import torch

    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch reports a damaged file with many exception types
        refused = re.search(r"GLOBAL ([\w.]+)", str(exc)) if isinstance(exc, pickle.UnpicklingError) else None
        if refused is not None:
            raise CheckpointError(
                f"checkpoint {path!r} is refused: it stores a Python object ({refused.group(1)}), and checkpoints "
                "are read weights-only (tensors and plain values), so that loading one never runs code from the "
                "file; write checkpoints with hbmp-bench train") from exc
        raise CheckpointError(f"cannot read checkpoint {path!r}: the file is truncated, damaged or not a torch "
                              f"checkpoint ({type(exc).__name__})") from exc
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path!r} is not an hbmp_bench checkpoint (format {CHECKPOINT_FORMAT})")
    if checkpoint.get("kind") not in kinds:
        raise CheckpointError(f"{path!r} holds a {checkpoint.get('kind')!r} policy; expected one of {kinds}")
    check_network_classes(checkpoint, path)
    return current_class_names(checkpoint)


def _class_names(value: Any, where: str):
    """(where, value) of every ``class_name`` entry in nested dicts and lists."""
    if isinstance(value, dict):
        for k, v in value.items():
            if k == "class_name":
                yield f"{where}.class_name", v
            else:
                yield from _class_names(v, f"{where}.{k}")
    elif isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            yield from _class_names(v, f"{where}[{k}]")


def current_class_names(value: Any) -> Any:
    """``value`` (a checkpoint or part of one) with every ``class_name`` of :data:`FORMER_NETWORK_CLASSES`
    replaced by the name of the class it became (a new dict; tensors are shared, not copied)."""
    if isinstance(value, dict):
        return {k: FORMER_NETWORK_CLASSES.get(v, v) if k == "class_name" and isinstance(v, str)
                else current_class_names(v) for k, v in value.items()}
    if isinstance(value, list):
        return [current_class_names(v) for v in value]
    return value


def check_network_classes(checkpoint: dict[str, Any], path: str = "checkpoint") -> None:
    """Refuse a checkpoint whose model config names a class outside ``NETWORK_CLASSES``.

    rsl-rl imports the module a ``class_name`` names and calls what it finds there, so a file
    naming ``some_module:anything`` would run that module's code in whichever process builds the
    policy (the evaluator's agent process, a training run). Raises ``CheckpointError`` naming the
    entry, the class it names and the allowed ones.
    """
    for where, name in _class_names(checkpoint.get("model"), "model"):
        if name not in NETWORK_CLASSES and name not in FORMER_NETWORK_CLASSES:
            raise CheckpointError(
                f"checkpoint {path!r} is refused: {where} is {name!r}, and a checkpoint may only build the "
                f"package's own networks ({', '.join(NETWORK_CLASSES)}); write checkpoints with hbmp-bench train")


def policy_only(checkpoint: dict[str, Any]) -> dict[str, Any]:
    """The checkpoint without the optimizer state (what ships with the package)."""
    return {k: v for k, v in checkpoint.items() if k not in ("optimizer_state_dict", "format")}


def actor_only(checkpoint: dict[str, Any]) -> dict[str, Any]:
    """What an agent needs of a checkpoint: kind, model, actor weights, progress and options (no critic,
    anchor or optimizer; ~1 MB for the paper's network)."""
    return {k: checkpoint[k] for k in ("kind", "model", "actor_state_dict", "progress", "train") if k in checkpoint}


def build_actor(checkpoint: dict[str, Any]):
    """The policy network of a checkpoint, weights loaded, in eval mode (its classes checked
    against ``NETWORK_CLASSES`` first, also for a checkpoint dict that did not come from
    ``load_checkpoint``)."""
    from hbmp_bench.policies.networks import build_model

    check_network_classes(checkpoint)
    model = current_class_names(checkpoint["model"])
    shapes = {k: tuple(v) for k, v in model["obs_shapes"].items()}
    actor = build_model(model["actor"], shapes, model["obs_groups"], "actor", model["num_actions"])
    actor.load_state_dict(checkpoint["actor_state_dict"])
    return actor.eval()
