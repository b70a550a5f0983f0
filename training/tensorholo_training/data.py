"""Reader of the layered-depth-image (LDI) hologram dataset written by ``holo dataset``.

Format: ``docs/DATASET.md`` (``format = "tensorholo-ldi-hologram-dataset"``, ``format_version = 1``):

``<root>/manifest.json``
    ``splits``: a list of ``{"name": "train"|"val"|"test", "samples": n, "shards": [{"file", "samples",
    "first_index"}]}``; ``resolution`` ``[H, W]``; ``ldi_layers`` ``L``; ``optics``: ``wavelengths_m``,
    ``pixel_pitch_m``, ``volume_depth_m``; ``synthesis``: SM-LBM parameters incl. ``pad``/``band_limit``.
    Also accepted: ``splits`` as an object ``{name: [files] | {"shards": [...]}}``, display keys at the top
    level or under ``display``/``setup``, and no manifest at all (shards found as ``<split>-*.npz``,
    ``<split>_*.npz`` or ``<split>/*.npz``). Other formats and newer versions are refused.

``<root>/<split>-<nnnnn>.npz`` (``numpy.savez`` or ``savez_compressed``), ``N`` scenes each:

- ``ldi`` float32 ``[N, 4·L, H, W]``: per layer ``r, g, b`` amplitude (√ of linear intensity) then
  normalised depth ``d`` (0 = near); invalid pixels have amplitude 0 and depth 1;
- ``ldi_valid`` uint8 ``[N, L, H, W]`` (1 = valid); optional (derived from amplitude/depth if absent);
- ``midpoint`` complex64 ``[N, 3, H, W]``: the SM-LBM midpoint hologram (R, G, B), or ``midpoint_re`` and
  ``midpoint_im`` float32 ``[N, 3, H, W]``;
- ``seed``, ``index`` uint64 ``[N]`` (ignored here).

The RGB-D input of the RGB-D CNN is the first layer's 4 channels; the LDI CNN reads all ``4·L``.
"""
from __future__ import annotations

import glob
import json
import math
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from .optics import Display, PropagationOptions, propagate


@dataclass
class Augment:
    """Augmentation options (applied identically to the LDI and the hologram).

    Attributes:
        crop: ``(h, w)`` random crop size in pixels, or ``None`` (full frames).
        hflip: random horizontal flips (probability 0.5).
        vflip: random vertical flips (probability 0.5).
    """

    crop: tuple[int, int] | None = None
    hflip: bool = False
    vflip: bool = False


FORMAT = "tensorholo-ldi-hologram-dataset"
FORMAT_VERSION = 1


def _shard_file(entry) -> str:
    return entry["file"] if isinstance(entry, dict) else entry


def split_names(manifest: dict) -> list[str]:
    """Names of the splits a manifest lists with at least one shard (``[]`` if it lists none)."""
    splits = manifest.get("splits")
    if isinstance(splits, list):
        return [s["name"] for s in splits if s.get("shards")]
    if isinstance(splits, dict):
        return [k for k, v in splits.items() if (v.get("shards", v.get("files")) if isinstance(v, dict) else v)]
    return []


def _split_shards(root: str, manifest: dict, split: str) -> list[str]:
    splits = manifest.get("splits")
    entries = None
    if isinstance(splits, list):
        entry = next((s for s in splits if s.get("name") == split), None)
        entries = entry.get("shards", []) if entry is not None else []
    elif isinstance(splits, dict) and split in splits:
        entries = splits[split]
        if isinstance(entries, dict):
            entries = entries.get("shards", entries.get("files", []))
    if entries is not None:
        return [os.path.join(root, _shard_file(e)) for e in entries]
    found: list[str] = []
    for pattern in (f"{split}/*.npz", f"{split}-*.npz", f"{split}_*.npz"):
        found += sorted(glob.glob(os.path.join(root, pattern)))
    return found


def read_manifest(root: str) -> dict:
    """The dataset's ``manifest.json`` as a dict (``{}`` if absent)."""
    path = os.path.join(root, "manifest.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        m = json.load(f)
    fmt, version = m.get("format"), m.get("format_version", 1)
    if fmt is not None and fmt != FORMAT:
        raise ValueError(f"{path}: format {fmt!r} is not {FORMAT!r}")
    if int(version) > FORMAT_VERSION:
        raise ValueError(f"{path}: format_version {version} is newer than this reader ({FORMAT_VERSION})")
    return m


def manifest_display(manifest: dict) -> Display | None:
    """The display geometry a dataset was generated for, or ``None`` if the manifest does not say."""
    for src in (manifest.get("optics", {}), manifest, manifest.get("display", {}), manifest.get("setup", {})):
        if isinstance(src, dict) and "wavelengths_m" in src:
            return Display(
                wavelengths_m=tuple(float(v) for v in src["wavelengths_m"]),
                pixel_pitch_m=float(src.get("pixel_pitch_m", Display.pixel_pitch_m)),
                volume_depth_m=float(src.get("volume_depth_m", Display.volume_depth_m)),
            )
    return None


def manifest_propagation(manifest: dict) -> PropagationOptions | None:
    """The ASM options the dataset's holograms were synthesised with (``synthesis.pad``/``band_limit``), or
    ``None`` if the manifest does not say. Focal-stack losses should use the same, so that the target focal
    stack is what the data means (``docs/DATASET.md``: "no padding unless ``synthesis.pad``")."""
    syn = manifest.get("synthesis")
    if not isinstance(syn, dict) or "pad" not in syn:
        return None
    return PropagationOptions(bool(syn.get("pad", False)), bool(syn.get("band_limit", False)))


def check_display(manifest: dict, display: Display, rel_tol: float = 1e-6) -> None:
    """Raises ``ValueError`` if the manifest's display geometry differs from ``display``."""
    d = manifest_display(manifest)
    if d is None:
        return
    pairs = list(zip(d.wavelengths_m, display.wavelengths_m)) + [
        (d.pixel_pitch_m, display.pixel_pitch_m),
        (d.volume_depth_m, display.volume_depth_m),
    ]
    if len(d.wavelengths_m) != len(display.wavelengths_m) or any(
        not math.isclose(a, b, rel_tol=rel_tol) for a, b in pairs
    ):
        raise ValueError(f"dataset was generated for {d}, but the training configuration uses {display}")


def load_shard(path: str) -> dict[str, np.ndarray]:
    """Loads one ``.npz`` shard into memory.

    Returns:
        ``{"ldi": float32 [N, 4L, H, W], "valid": uint8 [N, L, H, W], "midpoint": complex64 [N, 3, H, W]}``.
    Raises:
        ValueError naming the file and the missing/ill-shaped array.
    """
    with np.load(path) as z:
        keys = set(z.files)
        if "ldi" not in keys:
            raise ValueError(f"{path}: no 'ldi' array (has {sorted(keys)})")
        ldi = np.asarray(z["ldi"], dtype=np.float32)
        if "midpoint" in keys:
            mid = np.asarray(z["midpoint"]).astype(np.complex64)
        elif "midpoint_re" in keys and "midpoint_im" in keys:
            mid = (z["midpoint_re"].astype(np.float32) + 1j * z["midpoint_im"].astype(np.float32)).astype(
                np.complex64
            )
        else:
            raise ValueError(f"{path}: no 'midpoint' (complex64) nor 'midpoint_re'/'midpoint_im' arrays")
        if ldi.ndim != 4 or ldi.shape[1] % 4:
            raise ValueError(f"{path}: 'ldi' must be [N, 4·L, H, W], got {ldi.shape}")
        n, c4, h, w = ldi.shape
        if mid.shape != (n, 3, h, w):
            raise ValueError(f"{path}: 'midpoint' must be [{n}, 3, {h}, {w}], got {mid.shape}")
        if "ldi_valid" in keys:
            valid = np.asarray(z["ldi_valid"], dtype=np.uint8)
        else:
            layers = ldi.reshape(n, c4 // 4, 4, h, w)
            valid = ((layers[:, :, :3].max(axis=2) > 0) | (layers[:, :, 3] < 1)).astype(np.uint8)
    return {"ldi": ldi, "valid": valid, "midpoint": mid}


class LdiDataset(torch.utils.data.Dataset):
    """Map-style dataset over the samples of one split (the manifest's shards, read with NumPy).

    Each item is a dict:

    - ``"rgbd"``: float32 ``[4·L_in, h, w]`` network input (``L_in`` = ``input_layers``; per layer r, g, b, d);
    - ``"depth"``: float32 ``[h, w]`` first-layer normalised depth (for the dynamic focal stack);
    - ``"ldi_depth"``: float32 ``[L, h, w]`` every layer's normalised depth (the focal stack attention of
      ``fs_attention = "layers"``);
    - ``"valid"``: uint8 ``[L, h, w]``;
    - ``"midpoint"``: complex64 ``[3, h, w]`` ground-truth midpoint hologram.

    ``dataset[k]`` crops/flips with ``self.rng``; ``dataset[(k, epoch)]`` (what
    :class:`ShardGroupedBatchSampler` yields) with a generator seeded by ``(seed, epoch, k)``, so an item's
    augmentation does not depend on the process, the DataLoader worker or the order that reads it.
    A shard is decoded whole; the last ``cache_shards`` decoded shards are kept (per process: each DataLoader
    worker has its own copy). The shard-grouped sampler makes a worker read one shard after another, so the
    cache needs about one shard per sample of a batch.

    Args:
        root: dataset folder (with ``manifest.json``).
        split: ``"train"``, ``"val"`` or ``"test"``.
        input_layers: 1 (RGB-D: the first LDI layer) or the dataset's ``L`` (full LDI).
        augment: crops/flips (``None`` for none; validation should use none).
        cache_shards: decoded shards kept in memory per process.
        seed: seed of the augmentation.
    """

    def __init__(
        self,
        root: str,
        split: str = "train",
        input_layers: int = 1,
        augment: Augment | None = None,
        cache_shards: int = 2,
        seed: int = 0,
    ):
        self.root = root
        self.split = split
        self.manifest = read_manifest(root)
        self.shards = _split_shards(root, self.manifest, split)
        if not self.shards:
            raise FileNotFoundError(f"no shards for split '{split}' in {root}")
        self.input_layers = input_layers
        self.augment = augment or Augment()
        self.cache_shards = max(1, cache_shards)
        self._cache: dict[int, dict] = {}
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.index: list[tuple[int, int]] = []
        self.shard_sizes: list[int] = []
        self.layers = None
        for s, path in enumerate(self.shards):
            with np.load(path) as z:
                if "ldi" not in z.files:
                    raise ValueError(f"{path}: no 'ldi' array (has {sorted(z.files)})")
                shape = _npz_shape(z, "ldi")
            n = shape[0]
            self.layers = shape[1] // 4
            self.shape = tuple(shape[2:])
            self.index += [(s, i) for i in range(n)]
            self.shard_sizes.append(n)
        if input_layers < 1 or input_layers > self.layers:
            raise ValueError(f"input_layers must be in [1, {self.layers}], got {input_layers}")
        self.decoded = 0  # shards decoded by this process (a DataLoader worker counts its own)

    def __len__(self) -> int:
        return len(self.index)

    def _shard(self, s: int) -> dict:
        if s in self._cache:
            self._cache[s] = self._cache.pop(s)  # most recent last
            return self._cache[s]
        data = load_shard(self.shards[s])
        self.decoded += 1
        self._cache[s] = data
        while len(self._cache) > self.cache_shards:
            self._cache.pop(next(iter(self._cache)))
        return data

    def __getitem__(self, k) -> dict:
        if isinstance(k, tuple):
            k, epoch = k
            rng = np.random.default_rng([self.seed, epoch, k])
        else:
            rng = self.rng
        s, i = self.index[k]
        d = self._shard(s)
        ldi = d["ldi"][i]
        valid = d["valid"][i]
        mid = d["midpoint"][i]
        h, w = ldi.shape[-2:]
        a = self.augment
        if a.crop is not None:
            ch, cw = a.crop
            if ch > h or cw > w:
                raise ValueError(f"crop {a.crop} larger than the {h}×{w} frames")
            y0 = int(rng.integers(0, h - ch + 1))
            x0 = int(rng.integers(0, w - cw + 1))
            sl = (Ellipsis, slice(y0, y0 + ch), slice(x0, x0 + cw))
            ldi, valid, mid = ldi[sl], valid[sl], mid[sl]
        if a.hflip and rng.random() < 0.5:
            ldi, valid, mid = ldi[..., ::-1], valid[..., ::-1], mid[..., ::-1]
        if a.vflip and rng.random() < 0.5:
            ldi, valid, mid = ldi[..., ::-1, :], valid[..., ::-1, :], mid[..., ::-1, :]
        ldi = np.ascontiguousarray(ldi)
        return {
            "rgbd": torch.from_numpy(ldi[: 4 * self.input_layers].copy()),
            "depth": torch.from_numpy(ldi[3].copy()),
            "ldi_depth": torch.from_numpy(ldi[3::4].copy()),
            "valid": torch.from_numpy(np.ascontiguousarray(valid)),
            "midpoint": torch.from_numpy(np.ascontiguousarray(mid)),
        }


class ShardGroupedBatchSampler(torch.utils.data.Sampler):
    """Batches of one rank for one epoch, shard-grouped, disjoint across ranks (a ``batch_sampler`` of
    :class:`torch.utils.data.DataLoader` over :class:`LdiDataset`).

    The epoch's order depends only on ``(seed, epoch)`` and the **global batch** ``G = batch_size ·
    world_size``, never on the rank count alone, the DataLoader workers or the process:

    1. the shards are shuffled, and the samples within each shard (``numpy.random.default_rng([seed,
       epoch])``), giving one shard-grouped sequence of the ``N`` samples;
    2. the epoch has ``S = N // G`` steps. The last ``N − S·G`` samples of that sequence are **dropped** for
       this epoch (fewer than ``G``; they are different samples every epoch, since the order is reshuffled);
    3. the remaining ``S·G`` samples are cut into ``G`` contiguous **lanes** of ``S`` samples; global batch
       ``t`` is ``[lane_0[t], …, lane_{G−1}[t]]`` and rank ``r`` takes lanes ``r·b … r·b + b − 1``
       (``b = batch_size``).

    So each rank's samples are disjoint from the other ranks' and together they cover the epoch (less the
    dropped tail); a rank reads ``b`` lanes, each a contiguous run of the shard-grouped sequence, so
    consecutive batches of a rank come from the same ``b`` shards (one shard at a time per lane) and a
    DataLoader worker decodes each of its rank's shards once per epoch (a cache of ``b + 1`` shards per
    worker suffices). ``world_size`` ranks × ``batch_size`` see exactly the batches of one process with
    batch ``G``.

    Items are ``(index, epoch)`` pairs (:meth:`LdiDataset.__getitem__` seeds the augmentation with them).
    :meth:`set_epoch` chooses the epoch and the first batch (a resumed run starts inside an epoch).
    """

    def __init__(self, shard_sizes: Sequence[int], batch_size: int, rank: int = 0, world_size: int = 1,
                 seed: int = 0):
        if not 0 <= rank < world_size:
            raise ValueError(f"rank {rank} outside world size {world_size}")
        self.shard_sizes = list(shard_sizes)
        self.batch_size = batch_size
        self.rank = rank
        self.world_size = world_size
        self.seed = seed
        self.global_batch = batch_size * world_size
        n = sum(self.shard_sizes)
        if n < self.global_batch:
            raise ValueError(f"{n} samples cannot fill one global batch of {self.global_batch} "
                             f"({world_size} ranks × {batch_size})")
        self.steps_per_epoch = n // self.global_batch
        self.epoch = 0
        self.start = 0

    def epoch_order(self, epoch: int) -> list[int]:
        """The shard-grouped sequence of all samples in epoch ``epoch`` (step 1 above)."""
        rng = np.random.default_rng([self.seed, epoch])
        firsts = np.concatenate([[0], np.cumsum(self.shard_sizes)[:-1]]).astype(int)
        order: list[int] = []
        for s in rng.permutation(len(self.shard_sizes)):
            order += [int(firsts[s]) + int(j) for j in rng.permutation(self.shard_sizes[s])]
        return order

    def global_batches(self, epoch: int) -> list[list[int]]:
        """Every global batch of epoch ``epoch``: ``S`` lists of ``G`` sample indices."""
        order, steps, g = self.epoch_order(epoch), self.steps_per_epoch, self.global_batch
        lanes = [order[j * steps:(j + 1) * steps] for j in range(g)]
        return [[lane[t] for lane in lanes] for t in range(steps)]

    def rank_batches(self, epoch: int) -> list[list[int]]:
        """This rank's batches of epoch ``epoch`` (``S`` lists of ``batch_size`` indices)."""
        lo = self.rank * self.batch_size
        return [b[lo:lo + self.batch_size] for b in self.global_batches(epoch)]

    def set_epoch(self, epoch: int, start: int = 0) -> None:
        """The epoch the next iteration yields, from its batch ``start`` on."""
        self.epoch, self.start = epoch, start

    def __len__(self) -> int:
        return self.steps_per_epoch - self.start

    def __iter__(self):
        e = self.epoch
        for batch in self.rank_batches(e)[self.start:]:
            yield [(k, e) for k in batch]


def _npz_shape(z, name: str) -> tuple[int, ...]:
    """Shape of an array in an open ``NpzFile`` without decompressing all of it when possible."""
    try:
        from numpy.lib import format as npformat

        with z.zip.open(name + ".npy") as f:
            version = npformat.read_magic(f)
            if version == (1, 0):
                shape, _, _ = npformat.read_array_header_1_0(f)
            else:
                shape, _, _ = npformat.read_array_header_2_0(f)
            return tuple(shape)
    except Exception:  # pragma: no cover - fall back to a full read
        return tuple(z[name].shape)


def collate(items: Sequence[dict]) -> dict:
    """Stacks dataset items into a batch (``rgbd`` ``[B, 4L, h, w]``, ``midpoint`` ``[B, 3, h, w]``, ...)."""
    return {k: torch.stack([it[k] for it in items]) for k in items[0]}


# --------------------------------------------------------------------------------------------------------------
# Synthetic data (tests, demos without `holo`): simple occluding shapes and a layer-based hologram.


def synthetic_ldi(rng: np.random.Generator, height: int, width: int, layers: int = 2) -> np.ndarray:
    """A random scene as an LDI: a textured background plus a few occluding discs/rectangles.

    Layer 0 is what the camera sees; layer 1 holds the background behind the shapes (valid only there);
    further layers are empty (amplitude 0, depth 1).

    Returns:
        float32 ``[4·layers, H, W]`` in the dataset layout (r, g, b amplitude, depth per layer).
    """
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    out = np.zeros((layers, 4, height, width), np.float32)
    out[:, 3] = 1.0
    bg_d = rng.uniform(0.6, 1.0)
    bg = np.stack([0.3 + 0.25 * np.sin(xx * rng.uniform(0.05, 0.4) + rng.uniform(0, 6) + c)
                   * np.cos(yy * rng.uniform(0.05, 0.4)) for c in range(3)])
    bg = np.clip(bg, 0.02, 1.0)
    first = np.concatenate([bg, np.full((1, height, width), bg_d, np.float32)])
    covered = np.zeros((height, width), bool)
    for _ in range(int(rng.integers(1, 4))):
        d = rng.uniform(0.0, bg_d - 0.1)
        cy, cx = rng.uniform(0, height), rng.uniform(0, width)
        r = rng.uniform(0.1, 0.3) * min(height, width)
        if rng.random() < 0.5:
            m = (yy - cy) ** 2 + (xx - cx) ** 2 < r * r
        else:
            m = (np.abs(yy - cy) < r) & (np.abs(xx - cx) < 0.6 * r)
        m &= d < first[3]
        colour = rng.uniform(0.2, 1.0, size=3).astype(np.float32)
        for c in range(3):
            first[c][m] = colour[c] * (0.8 + 0.2 * np.cos(xx[m] * 0.3))
        first[3][m] = d
        covered |= m
    out[0] = first
    if layers > 1:
        out[1, :3] = np.where(covered, bg, 0.0)
        out[1, 3] = np.where(covered, bg_d, 1.0)
    return out.reshape(layers * 4, height, width)


def layered_hologram(
    ldi: np.ndarray,
    display: Display = Display(),
    planes: int = 16,
    options: PropagationOptions = PropagationOptions(pad=True),
) -> np.ndarray:
    """A simple midpoint hologram of the first LDI layer: depth quantised to ``planes`` planes, each plane's
    amplitude propagated from ``z(d)`` to the midpoint (``ASM(·, −z(d))``) and summed. No occlusion handling:
    a stand-in for SM-LBM in tests, not a training target of the paper's quality.

    Args:
        ldi: float32 ``[4·L, H, W]``.
    Returns:
        complex64 ``[3, H, W]``.
    """
    amp = torch.from_numpy(ldi[:3].astype(np.float32))
    depth = torch.from_numpy(ldi[3].astype(np.float32))
    q = torch.clamp((depth * planes).long(), 0, planes - 1)
    total = torch.zeros((3,) + tuple(amp.shape[-2:]), dtype=torch.complex64)
    for k in range(planes):
        m = q == k
        if not bool(m.any()):
            continue
        d = (k + 0.5) / planes
        layer = (amp * m).to(torch.complex64)
        total += propagate(layer, -display.depth_to_z(d), display.wavelengths_m, display.pixel_pitch_m,
                           "remove", options)
    return total.numpy()


def write_synthetic_dataset(
    root: str,
    counts: dict[str, int] | None = None,
    height: int = 32,
    width: int = 32,
    layers: int = 2,
    per_shard: int = 8,
    display: Display = Display(),
    seed: int = 0,
    complex_key: bool = True,
) -> str:
    """Writes a small synthetic dataset in the format above (for tests and CPU demos).

    Args:
        root: output folder (created).
        counts: scenes per split, default ``{"train": 16, "val": 4}``.
        height, width: frame size in pixels; layers: LDI layers ``L``.
        per_shard: scenes per ``.npz`` shard.
        display: geometry of the holograms (written to the manifest).
        seed: random seed.
        complex_key: store ``midpoint`` as complex64 (else ``midpoint_re``/``midpoint_im``).
    Returns:
        ``root``.
    """
    counts = counts or {"train": 16, "val": 4}
    rng = np.random.default_rng(seed)
    os.makedirs(root, exist_ok=True)
    splits = []
    for split, n in counts.items():
        files = []
        for start in range(0, n, per_shard):
            m = min(per_shard, n - start)
            ldi = np.stack([synthetic_ldi(rng, height, width, layers) for _ in range(m)])
            mid = np.stack([layered_hologram(x, display) for x in ldi])
            valid = np.stack([
                (x.reshape(layers, 4, height, width)[:, :3].max(axis=1) > 0).astype(np.uint8) for x in ldi
            ])
            name = f"{split}-{start // per_shard:05d}.npz"
            arrays = {"ldi": ldi, "ldi_valid": valid}
            if complex_key:
                arrays["midpoint"] = mid.astype(np.complex64)
            else:
                arrays["midpoint_re"] = mid.real.astype(np.float32)
                arrays["midpoint_im"] = mid.imag.astype(np.float32)
            np.savez(os.path.join(root, name), **arrays)
            files.append({"file": name, "samples": m, "first_index": start})
        splits.append({"name": split, "samples": n, "shards": files})
    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "generator": {"name": "tensorholo_training.data.write_synthetic_dataset",
                      "note": "synthetic test data: layer-based hologram of layer 0, no occlusion handling"},
        "resolution": [height, width],
        "ldi_layers": layers,
        "synthesis": {"method": "layer-based (no occlusion)", "levels": 16, "pad": True, "band_limit": False},
        "optics": display.to_dict(),
        "splits": splits,
    }
    with open(os.path.join(root, "manifest.json"), "w") as f:
        json.dump(manifest, f, indent=1)
    return root
