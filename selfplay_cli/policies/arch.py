"""A policy network's shape: the :class:`Arch` record (what a snapshot stores to rebuild its network) and the
convolutional encoder's layers an image seat gets (:func:`default_conv`, :func:`parse_conv`, :func:`conv_shapes`).

Plain Python: a snapshot's arch is checked here (against :data:`MAX_CONV_LAYERS` and its kin, and by
:func:`~selfplay_cli.policies.snapshot_format.expected_tensors` against its limits) before torch builds anything.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from ..errors import MarlError, MarlIOError

KINDS = ("mlp", "cnn")
LAYOUTS = ("hwc", "chw")  # where an image's channels are: last (HxWxC) or first (CxHxW)
NATURE_CNN = ((32, 8, 4), (64, 4, 2), (64, 3, 1))  # (channels, kernel, stride) per layer: DQN's Atari encoder
SMALL_CNN = ((16, 3, 1), (32, 3, 2))  # for images with a smaller side of 7 to 63 pixels (16x16 suite games)
ACTIVATION_NAMES = ("tanh", "relu")


class SnapshotError(MarlError):
    """A snapshot file (or the network it describes) that cannot be saved, read or played.

    Messages about a file always start with the file's path. Defined here, the lowest of the modules that raise it
    (a network's arch; the network; the snapshot format, reader and policy building).
    """


class SnapshotWriteError(SnapshotError, MarlIOError):
    """A snapshot file that could not be written for a reason outside marl (a full disk, a quota, permissions, a file
    size limit): an I/O error (exit 4), not a mistake in the snapshot."""


@dataclass(frozen=True)
class Arch:
    """The shape of a policy network: everything needed (with the env's spaces) to rebuild it from weights.

    ``kind`` is ``mlp`` or ``cnn`` (a convolutional encoder in front of the trunk, for image observations);
    ``conv`` the encoder's layers as ``(channels, kernel, stride)`` (text ``"16x3s1,32x3s2"`` is read too): None
    (the default) means "by the observation": :meth:`for_obs` gives an image seat :func:`default_conv` and any other
    seat the MLP alone; ``()`` never a CNN (an image's pixels flattened into the MLP); ``layout`` where a cnn's
    image keeps its channels (``hwc`` or ``chw``, set by :meth:`for_obs`). ``hidden`` the widths of the trunk's
    layers (after the encoder, if any); ``activation``
    ``tanh`` or ``relu``; ``value_head`` adds a state-value output (PPO's critic); ``dueling`` makes the action
    head a dueling Q head (``V(s) + A(s, a) - mean_a A(s, a)``, for DQN); ``squash`` makes a Box action head a
    tanh-squashed Gaussian with a state-dependent std (SAC's actor: a second head gives the log-std). Invalid values
    raise :class:`SnapshotError` (a user-facing error). ``squash`` is written out only when true, and ``conv`` and
    ``layout`` only when set, so every network without them is described exactly as before they existed.
    """

    kind: str = "mlp"
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    value_head: bool = True
    dueling: bool = False
    squash: bool = False
    conv: tuple[tuple[int, int, int], ...] | str | None = None  # text is read (parse_conv) into the triples
    layout: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "conv", parse_conv(self.conv))
        if self.kind not in KINDS:
            raise SnapshotError(f"unknown network kind {self.kind!r}; known: {', '.join(KINDS)}")
        if self.activation not in ACTIVATION_NAMES:
            raise SnapshotError(f"unknown activation {self.activation!r}; known: {', '.join(ACTIVATION_NAMES)}")
        try:
            hidden = tuple(self.hidden)
        except TypeError:
            raise SnapshotError(f"hidden layer sizes must be a list of integers, not {self.hidden!r}") from None
        if not all(isinstance(h, (int, np.integer)) and not isinstance(h, bool) and h > 0 for h in hidden):
            raise SnapshotError(f"hidden layer sizes must be positive integers, not {list(hidden)!r}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in hidden))
        for name in ("value_head", "dueling", "squash"):
            if not isinstance(getattr(self, name), bool):
                raise SnapshotError(f"arch field {name!r} must be true or false, not {getattr(self, name)!r}")
        if self.kind == "cnn" and (not self.conv or self.layout not in LAYOUTS):
            raise SnapshotError(f"a cnn arch needs its conv layers and the image's layout ({' or '.join(LAYOUTS)}), "
                                f"not conv {self.conv!r} and layout {self.layout!r}")
        if self.kind == "mlp" and self.layout:
            raise SnapshotError(f"an mlp arch has no image layout (not {self.layout!r})")

    def for_obs(self, space: spaces.Space) -> Arch:
        """This arch for a seat observing ``space`` (before any frame stacking): an image gets a cnn (the ``conv``
        asked for, else :func:`default_conv`) unless ``conv`` is ``()``; other observations the MLP. An arch
        already resolved (a cnn) is returned as it is. Conv layers for a seat that does not observe an image are a
        :class:`SnapshotError`."""
        if self.kind == "cnn":
            return self
        from ..envs.obs_spaces import image_layout

        layout = image_layout(space)
        if layout is None:
            if self.conv:
                raise SnapshotError(f"conv layers ({format_conv(self.conv)}) read images (uint8 HxWxC or CxHxW, 1 to "
                                    f"4 channels); this seat observes {_describe(space)}")
            return self
        if self.conv == ():
            return self
        h, w = space.shape[:2] if layout == "hwc" else space.shape[1:]
        return dataclasses.replace(self, kind="cnn", conv=self.conv or default_conv(h, w), layout=layout)

    def to_dict(self) -> dict[str, Any]:
        d = {
            "kind": self.kind,
            "hidden": list(self.hidden),
            "activation": self.activation,
            "value_head": self.value_head,
            "dueling": self.dueling,
        }
        if self.squash:
            d["squash"] = True
        if self.conv is not None:
            d["conv"] = [list(layer) for layer in self.conv]
        if self.layout:
            d["layout"] = self.layout
        return d

    @classmethod
    def from_dict(cls, data: Any) -> Arch:
        """Inverse of :meth:`to_dict`; missing fields take their defaults, unknown fields are refused."""
        if not isinstance(data, dict):
            raise SnapshotError(f"network arch must be an object, not {type(data).__name__}")
        known = {"kind", "hidden", "activation", "value_head", "dueling", "squash", "conv", "layout"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise SnapshotError(f"unknown network arch field(s) {', '.join(map(str, unknown))}")
        return cls(**data)

    def describe(self) -> str:
        """Short human form, e.g. ``mlp 64x64 tanh +value``."""
        parts = [self.kind]
        if self.kind == "cnn":
            parts += [format_conv(self.conv or ()), self.layout, "+"]
        parts += ["x".join(map(str, self.hidden)) or "linear", self.activation]
        if self.value_head:
            parts.append("+value")
        if self.dueling:
            parts.append("dueling")
        if self.squash:
            parts.append("tanh-gaussian")
        return " ".join(parts)


MAX_FRAME_STACK = 16  # observations a policy reads at once (a snapshot's frame_stack; selfplay_cli.play.frames)
MAX_CONV_LAYERS = 16
MAX_KERNEL = 32
MAX_STRIDE = 16
MAX_WIDTH_CONV = 4096  # channels of a conv layer


def parse_conv(value: Any) -> tuple[tuple[int, int, int], ...] | None:
    """Conv layers as ``(channels, kernel, stride)`` triples, from triples or text (``"32x8s4,64x4s2"``; ``""`` or
    ``"none"``: no conv layers); None stays None. A :class:`SnapshotError` for anything else."""
    if value is None:
        return None
    if isinstance(value, str):
        text = value.strip().lower()
        if text in ("", "none"):
            return ()
        layers = []
        for part in text.split(","):
            c, sep, rest = part.strip().partition("x")
            k, sep2, st = rest.partition("s")
            if not (sep and c.isdigit() and k.isdigit() and (not sep2 or st.isdigit())):
                raise SnapshotError(f"conv layer {part.strip()!r} is not CHANNELSxKERNELsSTRIDE (e.g. 32x8s4)")
            layers.append((int(c), int(k), int(st) if sep2 else 1))
        value = layers
    try:
        layers = [tuple(layer) for layer in value]
    except TypeError:
        raise SnapshotError(f"conv layers must be a list of [channels, kernel, stride], not {value!r}") from None
    if len(layers) > MAX_CONV_LAYERS:
        raise SnapshotError(f"{len(layers)} conv layers is more than marl builds ({MAX_CONV_LAYERS})")
    bounds = (MAX_WIDTH_CONV, MAX_KERNEL, MAX_STRIDE)
    for layer in layers:
        if not (len(layer) == 3 and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in layer)
                and all(1 <= v <= hi for v, hi in zip(layer, bounds, strict=True))):
            raise SnapshotError(f"conv layer {list(layer)[:4]!r} must be [channels, kernel, stride] of 1 to "
                                f"{MAX_WIDTH_CONV:,} channels, a kernel of 1 to {MAX_KERNEL}, a stride of 1 to "
                                f"{MAX_STRIDE}")
    return tuple((int(c), int(k), int(st)) for c, k, st in layers)



def format_conv(conv: tuple[tuple[int, int, int], ...]) -> str:
    """``32x8s4,64x4s2,64x3s1``: what :func:`parse_conv` reads."""
    return ",".join(f"{c}x{k}s{st}" for c, k, st in conv) or "none"


def default_conv(h: int, w: int) -> tuple[tuple[int, int, int], ...]:
    """The conv layers an image of ``h`` x ``w`` pixels gets by default: :data:`NATURE_CNN` where its smaller side
    has 64 pixels or more, :data:`SMALL_CNN` from 7, one ``16x3s1`` layer below."""
    side = min(int(h), int(w))
    return NATURE_CNN if side >= 64 else SMALL_CNN if side >= 7 else SMALL_CNN[:1]


def conv_shapes(obs_shape: tuple[int, ...], arch: Arch) -> tuple[list[tuple[int, int, int, int]], int]:
    """A cnn arch's conv weights ``(out, in, k, k)`` for observations of ``obs_shape``, and the width of the
    flattened output; a :class:`SnapshotError` where the observation is not an image of that layout or a layer
    leaves nothing to slide over."""
    if len(obs_shape) != 3:
        raise SnapshotError(f"a cnn reads images of three axes, not observations of shape {list(obs_shape)}")
    c, h, w = (obs_shape[2], *obs_shape[:2]) if arch.layout == "hwc" else obs_shape
    weights = []
    for out, k, st in arch.conv or ():
        if k > h or k > w:
            raise SnapshotError(f"conv layer {out}x{k}s{st} does not fit the {h}x{w} image it is given (observations "
                                f"{list(obs_shape)}, conv {format_conv(arch.conv or ())})")
        weights.append((out, c, k, k))
        c, h, w = out, (h - k) // st + 1, (w - k) // st + 1
    return weights, c * h * w


def _describe(space: spaces.Space) -> str:
    from ..envs.seat_spaces import describe_space

    return describe_space(space)
