"""Two-stage training of the hologram CNN (and the DDPM pre-filter CNN).

``python -m tensorholo_training.train --config CONFIG.json [--set key=value ...] [--run-dir DIR]``

Phases (``TrainConfig.stages``):

1. ``stage1``: supervised, hologram CNN only (data fidelity + dynamic focal stack + TV);
2. ``stage2``: DDPM, both CNNs (focal stack of the post-encoding hologram + TV + Eq. 11). The pre-filter CNN
   (when one is used: ``offset_mm != 0`` by default) starts as its base filter (AA-DPM or identity) by
   construction (:class:`.model.PrefilterCNN`), which stands in for the paper's identity pre-training.

Everything needed to resume lives in ``<run_dir>/checkpoint.pt`` (models, optimizer, phase and step, the
data order is a function of ``(seed, epoch)`` and the focal depths of ``(seed, step)``); a rerun of the same
command resumes where it stopped. The resolved configuration is saved as ``<run_dir>/config.json``; losses
and PSNRs go to ``<run_dir>/learning_curve.csv`` and stdout. ``<run_dir>/stage1.pt`` and ``final.pt`` are
written at the end of stage 1 and of the run (inputs of :mod:`.export`); ``best.pt`` holds the weights of the
best validation (``select_metric``) seen in the last phase, the checkpoint to export when the learning curve
is noisy.

The optics (``wavelengths_m``, ``pixel_pitch_m``, ``volume_depth_m``) come from the dataset's
``manifest.json`` (``optics``); a configuration value that contradicts it is refused (:func:`resolve_optics`).

Under ``torchrun`` (``RANK``/``WORLD_SIZE``/``LOCAL_RANK`` set) every process is a rank of a data-parallel job:
``init_process_group`` (nccl on CUDA, gloo on CPU), the CNNs wrapped in ``DistributedDataParallel``, each rank
reading its own part of every epoch (:class:`.data.ShardGroupedBatchSampler`); rank 0 alone writes files and
logs. The global batch is ``batch_size · world size`` and ``lr`` is scaled to it (``lr_scaling``). The
checkpoint records the world size; resuming under another one is refused unless ``allow_world_size_change``.
A restarted job (``torchrun --max-restarts``) resumes from ``checkpoint.pt`` like a rerun (``ckpt_every``).
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from . import losses as L
from . import optics
from .data import (
    Augment, LdiDataset, ShardGroupedBatchSampler, collate, manifest_display, manifest_propagation, read_manifest,
    split_names, write_synthetic_dataset,
)
from .metrics import psnr
from .model import count_parameters, hologram_cnn, load_prefilter_state, prefilter_cnn
from .optics import Display, PropagationOptions


@dataclass
class TrainConfig:
    """Training configuration (saved as JSON with the run). Units: SI except ``offset_mm`` (paper's mm).

    Data: ``dataset`` is a ``holo dataset`` folder, or ``"synthetic"`` for a small generated one
    (:func:`~.data.write_synthetic_dataset`, ``synthetic_size``/``synthetic_counts``) written into the run.
    Schedule: ``*_steps`` optimizer steps per phase; a positive ``*_epochs`` overrides them
    (``steps = ceil(epochs · N_train / batch_size)``; paper: 3000 / 50 / 1000 epochs, batch 2).
    """

    run_dir: str = "runs/small"
    dataset: str = "synthetic"
    synthetic_size: int = 64
    synthetic_counts: dict = field(default_factory=lambda: {"train": 32, "val": 8})
    input_layers: int = 1
    crop: list | None = None
    hflip: bool = True
    vflip: bool = True
    # models
    num_layers: int = 8
    channels: int = 24
    prefilter_layers: int = 8
    prefilter_channels: int = 8
    use_prefilter: str = "auto"  # "auto" (iff offset_mm != 0), "yes", "no"
    # the fixed filter the pre-filter CNN corrects (model.PrefilterCNN): "aa-dpm" (the SDK's AA-DPM Gaussian
    # blur, σ = aa_sigma_px, aa_kernel_size taps) or "identity" (plain DPM)
    prefilter_base: str = "aa-dpm"
    aa_sigma_px: float = 0.7
    aa_kernel_size: int = 5
    # display: None = the dataset's (manifest.json `optics`), the paper's 638/520/450 nm, 8 µm, 6 mm for a
    # dataset whose manifest does not say (and for "synthetic"). A value that contradicts the manifest is
    # refused, naming the key, unless optics_override (then the configuration wins: the focal-stack losses
    # then assume optics the holograms were not made with)
    wavelengths_m: list | None = None
    pixel_pitch_m: float | None = None
    volume_depth_m: float | None = None
    optics_override: bool = False
    offset_mm: float = 0.0
    # the aberrations the dataset's ground truth corrects (manifest.json `synthesis.aberration.profile`, a
    # tensorholo.aberration object: `holo dataset --aberration`, or `--display` with a profile's `aberration`),
    # set from the manifest (a value given here is replaced); recorded in the exported models' metadata
    # (`tensorholo.aberration`), so that the SDK runs them only with those aberrations and applies no
    # correction on top (docs/ABERRATION.md)
    aberration: dict | None = None
    # schedule
    stages: list = field(default_factory=lambda: ["stage1", "stage2"])
    batch_size: int = 2
    stage1_steps: int = 200
    stage2_steps: int = 100
    stage1_epochs: float = 0.0
    stage2_epochs: float = 0.0
    lr: float = 1e-4
    # learning rate rule for the global batch (batch_size · world size under torchrun): "linear" applies
    # lr · global_batch / lr_reference_batch (the paper's batch 2); "none" uses lr as given
    lr_scaling: str = "linear"
    lr_reference_batch: int = 2
    # learning rate within each phase: "constant" (paper) or "cosine" (from lr down to lr·lr_final_ratio over
    # the phase's steps: fine-tuning a shipped CNN on a short CPU budget)
    lr_schedule: str = "constant"
    lr_final_ratio: float = 0.1
    betas: list = field(default_factory=lambda: [0.9, 0.99])
    init_from: str = ""  # checkpoint (.pt) or shipped f32 ONNX file whose CNN(s) initialise this run
    # checkpoint (.pt) or shipped f32 ONNX file whose pre-filter initialises this run's (after init_from)
    init_prefilter_from: str = ""
    # stage 2 trains both CNNs (paper); False freezes the hologram CNN so that the pre-filter of one offset
    # serves every hologram CNN trained on the same optics (the SDK pairs any hologram CNN with a pre-filter)
    stage2_train_hologram: bool = True
    # losses
    data_mode: str = "complex"
    loss_kind: str = "l2"
    w_data: float = 1.0
    w_focal_stack: float = 1.0
    w_focal_stack_tv: float = 1.0
    w_regulariser: float = 0.07
    fs_bins: int = 200
    fs_top: int = 15
    fs_random: int = 5
    fs_attention_scale: float = 5.0
    # the depth the focal stack's attention and focal depths read: "front" (first layer, the paper) or
    # "layers" (nearest valid layer of the LDI: hidden points count where in focus; losses.attention_masks)
    fs_attention: str = "front"
    # quantisation-aware fine-tuning of the pre-filter (tensorholo_training.qat): its learned convolutions read
    # their inputs rounded to the u8 grids of this int8 QDQ pre-filter file (the exporter's, e.g.
    # `export --prefilter-only --int8` of the starting checkpoint) and use s8 weights; "" = off
    qat_grids_from: str = ""
    asm_pad: bool | None = None  # None: as the dataset's synthesis.pad (manifest), else False
    asm_band_limit: bool | None = None  # None: as the dataset's synthesis.band_limit, else False
    fs_chunk: int = 0
    # runtime
    device: str = "auto"  # "auto", "cpu", "cuda", "cuda:1", ...
    precision: str = "auto"  # "auto" (bf16/fp16 autocast on CUDA, fp32 on CPU), "fp32", "bf16", "fp16"
    threads: int = 0  # torch CPU threads (0 = torch's default)
    # DataLoader worker processes per rank that decode shards and crop/flip (0 = in the training process);
    # they persist across epochs, each with a cache of batch_size + 1 decoded shards
    num_workers: int = 2
    # a checkpoint written under another torchrun world size is refused unless this is true (the global
    # batch, hence the data order and the scaled learning rate, change with it)
    allow_world_size_change: bool = False
    seed: int = 0
    log_every: int = 10
    val_every: int = 50
    val_batches: int = 4
    ckpt_every: int = 50
    # validation metric whose best value in the last phase is kept as best.pt ("val_psnr_fs" or "val_psnr_amp")
    select_metric: str = "val_psnr_fs"

    # -- derived ------------------------------------------------------------------------------------------
    @property
    def display(self) -> Display:
        """The display geometry (keys left ``None`` read as the paper's; the :class:`Trainer` first resolves
        them from the dataset manifest)."""
        d = Display()
        return Display(
            tuple(self.wavelengths_m) if self.wavelengths_m is not None else d.wavelengths_m,
            d.pixel_pitch_m if self.pixel_pitch_m is None else float(self.pixel_pitch_m),
            d.volume_depth_m if self.volume_depth_m is None else float(self.volume_depth_m),
        )

    @property
    def offset_m(self) -> float:
        """SLM offset in metres."""
        return self.offset_mm * 1e-3

    @property
    def prefilter_enabled(self) -> bool:
        """Whether stage 2 uses the pre-filter CNN."""
        if self.use_prefilter == "auto":
            return self.offset_mm != 0.0
        return self.use_prefilter == "yes"

    @property
    def options(self) -> PropagationOptions:
        """ASM options of the losses and of the DDPM chain (``None`` fields read as False; the
        :class:`Trainer` first resolves them from the dataset manifest)."""
        return PropagationOptions(bool(self.asm_pad), bool(self.asm_band_limit))

    def fs_config(self) -> L.FocalStackLossConfig:
        """The focal stack loss configuration."""
        return L.FocalStackLossConfig(
            self.fs_bins, self.fs_top, self.fs_random, self.fs_attention_scale, self.loss_kind,
            bool(self.asm_pad), bool(self.asm_band_limit), self.fs_chunk or None,
        )

    def weights(self) -> L.LossWeights:
        """Loss weights."""
        return L.LossWeights(self.w_data, self.w_focal_stack, self.w_focal_stack_tv, self.w_regulariser)

    def to_dict(self) -> dict:
        """JSON-serialisable dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        """From a dict; unknown keys are an error (typos must not pass silently), except the keys of the
        removed identity pre-training (``identity_steps``, ``identity_epochs``, ``identity_target``), which
        configurations of older runs carry and which are ignored."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names - {"_comment", "training_commit", "world_size"} - REMOVED_KEYS
        if unknown:
            raise ValueError(f"unknown configuration keys: {sorted(unknown)}")
        return cls(**{k: v for k, v in d.items() if k in names})


#: Configuration keys of the identity pre-training phase, removed with the amplitude/phase pre-filter.
REMOVED_KEYS = frozenset({"identity_steps", "identity_epochs", "identity_target"})


def set_option(cfg: TrainConfig, assignment: str) -> TrainConfig:
    """Applies ``key=value`` (value parsed as JSON when possible, else a string) to a configuration."""
    key, sep, value = assignment.partition("=")
    if not sep:
        raise ValueError(f"--set expects key=value, got {assignment!r}")
    names = {f.name for f in dataclasses.fields(cfg)}
    if key not in names:
        raise ValueError(f"unknown configuration key {key!r}")
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        parsed = value
    return dataclasses.replace(cfg, **{key: parsed})


def git_commit() -> str:
    """``git rev-parse HEAD`` of the source tree (with ``-dirty`` if modified), or ``"unknown"``."""
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, check=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, check=True)
        return rev.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def resolve_device(cfg: TrainConfig) -> torch.device:
    """The torch device of a configuration (``auto``: CUDA when available)."""
    if cfg.device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(cfg.device)


def autocast_dtype(cfg: TrainConfig, device: torch.device) -> torch.dtype | None:
    """Autocast dtype of the CNNs (``None`` = float32). Optics always run in complex64/float64."""
    p = cfg.precision
    if p == "auto":
        if device.type != "cuda":
            return None
        return torch.bfloat16 if torch.cuda.is_bf16_supported() else torch.float16
    return {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}[p]


def widen_input_layers(state: dict, net) -> dict:
    """An RGB-D hologram CNN's weights (``4`` input channels) fitted to an LDI CNN of the same depth
    (``4·L`` channels): the first layer's and the last layer's input-channel weights for layer 0 are copied,
    those of the back layers set to zero, so that the LDI CNN starts as the RGB-D CNN exactly (whatever the back
    layers hold) and training adds what they tell. Any other state is returned unchanged (the same object)."""
    first, last = "convs.0.weight", f"convs.{net.num_layers - 1}.weight"
    if first not in state or state[first].shape[1] != 4 or net.in_channels == 4:
        return state
    out = dict(state)
    w0 = torch.zeros_like(net.convs[0].weight)
    w0[:, :4] = state[first]
    out[first] = w0
    wl = torch.zeros_like(net.convs[-1].weight)
    c = net.channels
    wl[:, :c] = state[last][:, :c]        # the hidden features
    wl[:, c:c + 4] = state[last][:, c:]   # the input's layer 0 (the last layer also sees the input)
    out[last] = wl
    return out


def initial_state(path: str, device) -> dict:
    """The weights a run starts from: ``{"net": ..., "prefilter": ...}`` (either may be ``None``) from a
    training checkpoint (``.pt``: ``checkpoint.pt``, ``stage1.pt``, ``best.pt``, ``final.pt``) or from a shipped
    f32 ONNX file (``models/holo30_rgbd.onnx``, ``models/prefilter_6mm.onnx``), whose initialisers carry the
    PyTorch parameter names. A run resumed from an ONNX file restarts its optimiser (Adam's moments are not
    in the file); the int8 files are refused (their weights are quantised)."""
    if not path.endswith(".onnx"):
        return torch.load(path, map_location=device, weights_only=False)
    import onnx
    from onnx import numpy_helper

    model = onnx.load(path)
    meta = {p.key: p.value for p in model.metadata_props}
    if meta.get("tensorholo.precision", "f32") != "f32":
        raise ValueError(f"{path}: an {meta['tensorholo.precision']} file; initialise from the f32 ONNX file")
    weights = {i.name: torch.from_numpy(numpy_helper.to_array(i).copy()).to(device)
               for i in model.graph.initializer}
    kind = meta.get("tensorholo.kind")
    if kind == "hologram-cnn":
        return {"net": weights, "prefilter": None}
    if kind == "prefilter-cnn":
        return {"net": None, "prefilter": weights}
    raise ValueError(f"{path}: tensorholo.kind is {kind!r}, neither hologram-cnn nor prefilter-cnn")


OPTICS_KEYS = ("wavelengths_m", "pixel_pitch_m", "volume_depth_m")


def resolve_optics(cfg: TrainConfig, manifest: dict, rel_tol: float = 1e-6) -> TrainConfig:
    """The configuration with its optics (``wavelengths_m``, ``pixel_pitch_m``, ``volume_depth_m``) taken from
    the dataset's manifest (``optics``; :func:`.data.manifest_display`), so that the display is stated once,
    in the dataset. A key the configuration sets is kept if it agrees with the manifest; if it contradicts it,
    ``ValueError`` names the key, unless ``optics_override``. Without optics in the manifest, keys left
    ``None`` become the paper's values."""
    m = manifest_display(manifest)
    source = m if m is not None else Display()
    values = {"wavelengths_m": [float(w) for w in source.wavelengths_m], "pixel_pitch_m": source.pixel_pitch_m,
              "volume_depth_m": source.volume_depth_m}
    out = {}
    for key in OPTICS_KEYS:
        given = getattr(cfg, key)
        if given is None:
            out[key] = values[key]
            continue
        a = [float(v) for v in given] if key == "wavelengths_m" else [float(given)]
        b = values[key] if key == "wavelengths_m" else [values[key]]
        agree = len(a) == len(b) and all(math.isclose(x, y, rel_tol=rel_tol) for x, y in zip(a, b))
        if m is not None and not agree and not cfg.optics_override:
            raise ValueError(
                f"{key}: the configuration says {given}, but the dataset was made for {values[key]} "
                f"(manifest.json `optics`); training reads the optics from the manifest, so drop `{key}` from the "
                "configuration, or set optics_override=true to train for other optics than the data's")
        out[key] = list(given) if key == "wavelengths_m" else float(given)
    return dataclasses.replace(cfg, **out, aberration=manifest_aberration(manifest))


def manifest_aberration(manifest: dict) -> dict | None:
    """The aberration profile (a ``tensorholo.aberration`` object) whose correction the dataset's ground truth
    holds (``synthesis.aberration.profile``), or ``None``."""
    syn = manifest.get("synthesis")
    ab = syn.get("aberration") if isinstance(syn, dict) else None
    return ab.get("profile") if isinstance(ab, dict) else None


@dataclass
class Dist:
    """The process's place in a torchrun job (``world_size == 1`` and ``enabled == False`` outside one)."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    enabled: bool = False

    @property
    def is_main(self) -> bool:
        """Rank 0: the only rank that writes files (checkpoints, CSV, config, synthetic data) and logs."""
        return self.rank == 0

    def barrier(self) -> None:
        if self.enabled:
            torch.distributed.barrier()


def init_distributed(device_kind: str) -> Dist:
    """Joins the torchrun job described by ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK`` (and ``MASTER_ADDR``/
    ``MASTER_PORT``) with ``torch.distributed.init_process_group`` (nccl on CUDA, gloo on CPU); a no-op outside
    torchrun. Idempotent (a second Trainer in the same process reuses the group)."""
    if "RANK" not in os.environ or "WORLD_SIZE" not in os.environ:
        return Dist()
    import torch.distributed as dist

    if not dist.is_initialized():
        backend = "nccl" if device_kind == "cuda" else "gloo"
        restart = os.environ.get("TORCHELASTIC_RESTART_COUNT", "0")
        if os.environ.get("TORCHELASTIC_USE_AGENT_STORE") == "True":
            # torchrun's agent keeps one store for all restarts: without a prefix of their own, the workers of
            # a restart can read the previous generation's gloo addresses and connect to dead processes
            # (observed with torch 2.15: "Connection reset by peer", or a hang, after --max-restarts restarts)
            from datetime import timedelta

            store = dist.TCPStore(os.environ["MASTER_ADDR"], int(os.environ["MASTER_PORT"]),
                                  int(os.environ["WORLD_SIZE"]), is_master=False, timeout=timedelta(minutes=10))
            dist.init_process_group(backend=backend, store=dist.PrefixStore(f"tensorholo/attempt_{restart}", store),
                                    rank=int(os.environ["RANK"]), world_size=int(os.environ["WORLD_SIZE"]))
        else:
            dist.init_process_group(backend=backend)
    return Dist(dist.get_rank(), dist.get_world_size(), int(os.environ.get("LOCAL_RANK", 0)), True)


def weights_digest(*modules) -> str:
    """SHA-256 of the parameters and buffers of ``modules`` (the ranks compare it after training)."""
    import hashlib

    h = hashlib.sha256()
    for m in modules:
        if m is None:
            continue
        for name, t in sorted(m.state_dict().items()):
            h.update(name.encode())
            h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


def _inject_fault(rank: int, step: int) -> None:
    """Test hook: ``TENSORHOLO_FAULT="RANK:STEP:MARKER"`` makes rank ``RANK`` exit (code 17) after step
    ``STEP`` once: the first time, it creates the file ``MARKER``; when ``MARKER`` exists it does nothing."""
    spec = os.environ.get("TENSORHOLO_FAULT")
    if not spec:
        return
    r, k, marker = spec.split(":", 2)
    if int(r) == rank and int(k) == step and not os.path.exists(marker):
        open(marker, "w").close()
        print(f"rank {rank}: injected fault after step {step}", flush=True)
        os._exit(17)


class Trainer:
    """Runs the phases of a :class:`TrainConfig` with checkpoints that resume (see the module docstring).

    Args:
        cfg: the configuration; ``cfg.run_dir`` is created.
        log: print function for progress lines.
    """

    def __init__(self, cfg: TrainConfig, log=print):
        self.cfg = cfg
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        torch.manual_seed(cfg.seed)
        self.device = resolve_device(cfg)
        self.dist = init_distributed(self.device.type)
        if self.dist.enabled and self.device.type == "cuda":
            self.device = torch.device("cuda", self.dist.local_rank)
            torch.cuda.set_device(self.device)
        self.log = log if self.dist.is_main else (lambda m: None)
        if self.dist.is_main:
            os.makedirs(cfg.run_dir, exist_ok=True)
        self.amp_dtype = autocast_dtype(cfg, self.device)
        root = cfg.dataset
        if root == "synthetic":
            root = os.path.join(cfg.run_dir, "synthetic_dataset")
            if self.dist.is_main and not os.path.exists(os.path.join(root, "manifest.json")):
                n = cfg.synthetic_size
                write_synthetic_dataset(root, dict(cfg.synthetic_counts), n, n, max(2, cfg.input_layers),
                                        display=cfg.display, seed=cfg.seed)
            self.dist.barrier()
        self.dataset_root = root
        manifest = read_manifest(root)
        cfg = self.cfg = resolve_optics(cfg, manifest)
        self.display = cfg.display
        if cfg.lr_scaling not in ("linear", "none"):
            raise ValueError(f"lr_scaling must be 'linear' or 'none', got {cfg.lr_scaling!r}")
        self.global_batch = cfg.batch_size * self.dist.world_size
        synth = manifest_propagation(manifest) or PropagationOptions()
        if cfg.asm_pad is None or cfg.asm_band_limit is None:
            cfg = dataclasses.replace(
                cfg,
                asm_pad=synth.pad if cfg.asm_pad is None else cfg.asm_pad,
                asm_band_limit=synth.band_limit if cfg.asm_band_limit is None else cfg.asm_band_limit,
            )
            self.cfg = cfg
        crop = tuple(cfg.crop) if isinstance(cfg.crop, (list, tuple)) else (
            (cfg.crop, cfg.crop) if cfg.crop else None)
        self.train_set = LdiDataset(root, "train", cfg.input_layers, Augment(crop, cfg.hflip, cfg.vflip),
                                    cache_shards=cfg.batch_size + 1, seed=cfg.seed)
        self.sampler = ShardGroupedBatchSampler(self.train_set.shard_sizes, cfg.batch_size, self.dist.rank,
                                                self.dist.world_size, cfg.seed)
        self.loader = torch.utils.data.DataLoader(
            self.train_set, batch_sampler=self.sampler, num_workers=cfg.num_workers, collate_fn=collate,
            persistent_workers=cfg.num_workers > 0, pin_memory=self.device.type == "cuda")
        names = split_names(manifest)
        val_split = next((s for s in ("val", "test") if s in names), None) if names else "val"
        try:
            self.val_set = (LdiDataset(root, val_split, cfg.input_layers, Augment(crop), seed=cfg.seed + 1)
                            if val_split else None)
        except FileNotFoundError:
            self.val_set = None
        self.trained_resolution = list(crop) if crop else list(self.train_set.shape)
        torch.manual_seed(cfg.seed)
        self.net = hologram_cnn(cfg.num_layers, cfg.input_layers, cfg.channels).to(self.device)
        self.prefilter = (
            prefilter_cnn(cfg.prefilter_layers, cfg.prefilter_channels, cfg.prefilter_base, cfg.aa_sigma_px,
                          cfg.aa_kernel_size).to(self.device)
            if cfg.prefilter_enabled else None
        )
        if cfg.select_metric not in ("val_psnr_fs", "val_psnr_amp"):
            raise ValueError(f"select_metric must be 'val_psnr_fs' or 'val_psnr_amp', not {cfg.select_metric!r}")
        if cfg.init_from:
            state = initial_state(cfg.init_from, self.device)
            if state.get("net") is None:
                raise ValueError(f"init_from {cfg.init_from}: holds no hologram CNN (a pre-filter file goes in "
                                 "init_prefilter_from)")
            net_state = state["net"]
            widened = widen_input_layers(net_state, self.net)
            self.net.load_state_dict(widened)
            if widened is not net_state:
                self.log(f"{cfg.init_from}: an RGB-D CNN; the weights of the LDI's back layers start at zero "
                         "(the network starts as the RGB-D one)")
            if self.prefilter is not None and state.get("prefilter") is not None:
                load_prefilter_state(self.prefilter, state["prefilter"], cfg.init_from)
            self.log(f"initialised from {cfg.init_from}")
        if cfg.init_prefilter_from:
            if self.prefilter is None:
                raise ValueError("init_prefilter_from needs a run with a pre-filter (stage2 at a non-zero offset)")
            state = initial_state(cfg.init_prefilter_from, self.device)
            if state.get("prefilter") is None:
                raise ValueError(f"init_prefilter_from {cfg.init_prefilter_from}: holds no pre-filter CNN")
            load_prefilter_state(self.prefilter, state["prefilter"], cfg.init_prefilter_from)
            self.log(f"pre-filter initialised from {cfg.init_prefilter_from}")
        if cfg.qat_grids_from:
            self._fake_quantise_prefilter()
        # the modules the training steps call: DistributedDataParallel wrappers under torchrun (DDP broadcasts
        # rank 0's weights when it wraps), the modules themselves otherwise
        self.net_train, self.prefilter_train = self.net, self.prefilter
        if self.dist.enabled:
            from torch.nn.parallel import DistributedDataParallel as DDP

            ids = [self.device.index] if self.device.type == "cuda" else None
            self.net_train = DDP(self.net, device_ids=ids)
            if self.prefilter is not None:
                self.prefilter_train = DDP(self.prefilter, device_ids=ids)
        self.best: dict = {}
        self.phases = self._phases()
        self.lr_at(0, 1)  # an unknown lr_schedule fails here, not after the first batch
        if cfg.fs_attention not in ("front", "layers"):  # so does an unknown attention depth
            raise ValueError(f"fs_attention must be 'front' or 'layers', got {cfg.fs_attention!r}")
        self.phase_index = 0
        self.phase_step = 0
        self.global_step = 0
        self.optimizer = None
        self.scaler = None
        self._new_optimizer()
        self.commit = git_commit()

    def _fake_quantise_prefilter(self) -> None:
        """``qat_grids_from``: the pre-filter rounds its convolutions' inputs on that int8 file's grids, with s8
        weights (:func:`.qat.fake_quantise`)."""
        from . import qat

        if self.prefilter is None:
            raise ValueError("qat_grids_from needs a pre-filter (stage2 at a non-zero offset)")
        grids = qat.file_grids(self.cfg.qat_grids_from)
        qat.fake_quantise(self.prefilter, grids)
        self.log(f"pre-filter fake-quantised on the {len(grids)} u8 grids of {self.cfg.qat_grids_from}")

    # -- schedule -----------------------------------------------------------------------------------------
    def _phases(self) -> list[tuple[str, int]]:
        cfg = self.cfg
        per_epoch = self.sampler.steps_per_epoch
        out = []
        for name in cfg.stages:
            if name == "identity":
                raise ValueError("the 'identity' stage was removed: the pre-filter CNN starts as its base filter "
                                 "(prefilter_base) by construction; drop it from `stages`")
            if name not in ("stage1", "stage2"):
                raise ValueError(f"unknown stage {name!r} (stage1, stage2)")
            epochs = getattr(cfg, f"{name}_epochs")
            steps = math.ceil(epochs * per_epoch) if epochs > 0 else getattr(cfg, f"{name}_steps")
            if steps > 0:
                out.append((name, int(steps)))
        return out

    @property
    def phase(self) -> str | None:
        """Name of the current phase (``None`` when done)."""
        return self.phases[self.phase_index][0] if self.phase_index < len(self.phases) else None

    def _params(self, phase: str | None):
        if phase == "stage2" and self.prefilter is not None:
            if not self.cfg.stage2_train_hologram:
                return list(self.prefilter.parameters())
            return list(self.net.parameters()) + list(self.prefilter.parameters())
        return list(self.net.parameters())

    def lr_at(self, phase_step: int, steps: int) -> float:
        """The learning rate of step ``phase_step`` (0-based) of a phase of ``steps`` steps (``lr_schedule``)."""
        cfg = self.cfg
        base = self.base_lr
        if cfg.lr_schedule == "constant":
            return base
        if cfg.lr_schedule != "cosine":
            raise ValueError(f"unknown lr_schedule {cfg.lr_schedule!r} (constant, cosine)")
        t = min(max(phase_step / max(steps - 1, 1), 0.0), 1.0)
        r = cfg.lr_final_ratio
        return base * (r + (1.0 - r) * 0.5 * (1.0 + math.cos(math.pi * t)))

    @property
    def base_lr(self) -> float:
        """``lr`` scaled to the global batch (``lr_scaling``): ``lr · global_batch / lr_reference_batch``."""
        if self.cfg.lr_scaling == "none":
            return self.cfg.lr
        return self.cfg.lr * self.global_batch / self.cfg.lr_reference_batch

    def _new_optimizer(self):
        self.optimizer = torch.optim.Adam(self._params(self.phase), lr=self.cfg.lr, betas=tuple(self.cfg.betas))
        self.scaler = torch.amp.GradScaler("cuda", enabled=self.amp_dtype == torch.float16)

    # -- one step -----------------------------------------------------------------------------------------
    def _autocast(self):
        if self.amp_dtype is None:
            return torch.autocast(self.device.type, enabled=False)
        return torch.autocast(self.device.type, dtype=self.amp_dtype)

    def _generator(self, step: int, salt: int = 0) -> torch.Generator:
        return torch.Generator().manual_seed(self.cfg.seed * 1_000_003 + step * 7 + salt)

    def _sample_generator(self, step: int, place: int) -> torch.Generator:
        """The generator of the focal planes of the sample at ``place`` in the global batch of ``step``: a
        function of ``(seed, step, place)`` only, so ranks draw what one process with the global batch draws."""
        state = np.random.SeedSequence([self.cfg.seed, step, place]).generate_state(1, np.uint64)[0]
        return torch.Generator().manual_seed(int(state) & ((1 << 63) - 1))

    def attention_depth(self, batch: dict) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The depth the focal stack's attention reads (``cfg.fs_attention``): the first layer's ``[B, H, W]``
        and ``None``, or every LDI layer's ``[B, L, H, W]`` and their valid mask ``[B, L, H, W]``."""
        if self.cfg.fs_attention == "layers":
            return batch["ldi_depth"].to(self.device), batch["valid"].to(self.device)
        return batch["depth"].to(self.device), None

    def compute_loss(self, batch: dict, phase: str, generator) -> dict:
        """Losses of one batch for ``phase`` (see :mod:`.losses`); also ``"pred"`` (complex midpoint used
        for PSNR: the CNN output in stage 1, the post-encoding hologram in stage 2)."""
        cfg = self.cfg
        rgbd = batch["rgbd"].to(self.device)
        gt = batch["midpoint"].to(self.device)
        depth, valid = self.attention_depth(batch)
        frozen = phase == "stage2" and not cfg.stage2_train_hologram
        net = self.net_train if torch.is_grad_enabled() else self.net
        prefilter = self.prefilter_train if torch.is_grad_enabled() else self.prefilter
        with self._autocast(), torch.set_grad_enabled(torch.is_grad_enabled() and not frozen):
            amp, phs = net(rgbd)
        amp, phs = amp.float(), phs.float()
        if phase == "stage1":
            out = L.stage1_loss(amp, phs, gt, depth, self.display, cfg.weights(), cfg.fs_config(),
                                cfg.data_mode, generator, valid)
            out["pred"] = optics.amp_phase_to_complex(amp, phs)
            return out
        with self._autocast():
            dd = L.ddpm_forward(amp, phs, prefilter, cfg.offset_m, self.display, cfg.options)
        out = L.stage2_loss(dd, gt, depth, self.display, cfg.weights(), cfg.fs_config(), generator, valid)
        out["pred"] = dd.post_midpoint
        return out

    def train_step(self, batch: dict) -> dict[str, float]:
        """One optimizer step of the current phase; returns the loss terms as floats."""
        phase = self.phase
        self.net.train(phase != "stage2" or self.cfg.stage2_train_hologram)
        first = self.dist.rank * self.cfg.batch_size  # this rank's samples' places in the global batch
        gens = [self._sample_generator(self.global_step, first + i) for i in range(len(batch["rgbd"]))]
        out = self.compute_loss(batch, phase, gens)
        lr = self.lr_at(self.phase_step, self.phases[self.phase_index][1])
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        self.optimizer.zero_grad(set_to_none=True)
        self.scaler.scale(out["total"]).backward()
        self.scaler.step(self.optimizer)
        self.scaler.update()
        return {k: float(v.detach()) for k, v in out.items() if k != "pred"}

    @torch.no_grad()
    def val_batches(self):
        """The fixed validation batches: ``(k, items, batch)`` for up to ``val_batches`` batches, each scene
        cropped with its own fixed seed, so every call (and every run) sees the same pixels."""
        bs = self.cfg.batch_size
        for k in range(0, min(len(self.val_set), bs * self.cfg.val_batches), bs):
            items = []
            for i in range(k, min(k + bs, len(self.val_set))):
                self.val_set.rng = np.random.default_rng([self.cfg.seed, 1_000_000, i])
                items.append(self.val_set[i])
            yield k, items, collate(items)

    def validate(self, phase: str) -> dict[str, float]:
        """Mean loss and PSNRs on up to ``val_batches`` validation batches (fixed focal depths per batch).

        ``psnr_amp``: amplitude of the predicted (stage 1) or post-encoding (stage 2) midpoint hologram vs
        the ground-truth amplitude, data range 1 (paper Table 2). ``psnr_fs``: the same over the focal stack
        of 15 most frequent + 5 random depths of each scene.
        """
        if self.val_set is None:
            return {}
        self.net.eval()
        totals, amp_psnr, fs_psnr, n = 0.0, [], [], 0
        for k, items, batch in self.val_batches():
            g = self._generator(k, salt=1)
            with torch.no_grad():
                out = self.compute_loss(batch, phase, g)
            totals += float(out["total"])
            n += 1
            gt = batch["midpoint"].to(self.device)
            pred = out["pred"]
            amp_psnr += psnr(gt.abs(), pred.abs()).tolist()
            depth, valid = self.attention_depth(batch)
            focal = L.select_focal_depths(depth, self.cfg.fs_bins, self.cfg.fs_top, self.cfg.fs_random,
                                          self._generator(k, salt=2), valid)
            opts = self.cfg.options
            s_gt = optics.focal_stack(gt, focal, self.display, 0.0, opts, chunk=self.cfg.fs_chunk or None)
            s_pr = optics.focal_stack(pred, focal, self.display, 0.0, opts, chunk=self.cfg.fs_chunk or None)
            fs_psnr += psnr(s_gt.flatten(0, 1), s_pr.flatten(0, 1)).view(len(items), -1).mean(1).tolist()
        return {"val_loss": totals / max(n, 1), "val_psnr_amp": float(np.mean(amp_psnr)),
                "val_psnr_fs": float(np.mean(fs_psnr))}

    # -- checkpoints --------------------------------------------------------------------------------------
    def state(self) -> dict:
        """Everything needed to resume (and to export)."""
        return {
            "config": self.cfg.to_dict(),
            "training_commit": self.commit,
            "trained_resolution": self.trained_resolution,
            "net": self.net.state_dict(),
            "prefilter": self.prefilter.state_dict() if self.prefilter is not None else None,
            "optimizer": self.optimizer.state_dict(),
            "scaler": self.scaler.state_dict(),
            "phase_index": self.phase_index,
            "phase_step": self.phase_step,
            "global_step": self.global_step,
            "phases": self.phases,
            "torch_rng": torch.get_rng_state(),
            "best": self.best,
            "world_size": self.dist.world_size,
            "global_batch": self.global_batch,
        }

    def save(self, name: str = "checkpoint.pt") -> str:
        """Writes ``<run_dir>/<name>`` atomically (rank 0 only; the others write nothing); returns its path."""
        path = os.path.join(self.cfg.run_dir, name)
        if not self.dist.is_main:
            return path
        tmp = path + ".tmp"
        torch.save(self.state(), tmp)
        os.replace(tmp, path)
        return path

    def load(self, path: str) -> None:
        """Restores a :meth:`state` written by :meth:`save`."""
        s = torch.load(path, map_location=self.device, weights_only=False)
        saved_world = int(s.get("world_size", 1))
        if saved_world != self.dist.world_size:
            if not self.cfg.allow_world_size_change:
                raise ValueError(
                    f"{path} was written by a run of world size {saved_world} (global batch "
                    f"{s.get('global_batch', '?')}), this one has {self.dist.world_size} (global batch "
                    f"{self.global_batch}): resuming would change the data order and the scaled learning rate. "
                    f"Resume with {saved_world} processes, or set allow_world_size_change=true")
            self.log(f"resuming a world-size-{saved_world} checkpoint with world size {self.dist.world_size} "
                     "(allow_world_size_change)")
        self.net.load_state_dict(s["net"])
        if self.prefilter is not None and s.get("prefilter") is not None:
            load_prefilter_state(self.prefilter, s["prefilter"], path)
        self.best = s.get("best", {})
        self.phase_index, self.phase_step, self.global_step = s["phase_index"], s["phase_step"], s["global_step"]
        finished = self.phase_index >= len(self.phases)
        if finished:
            # A finished run whose schedule has since been lengthened (more steps in the config) continues at
            # its global step, in whichever phase that step now falls; Adam restarts (its moments are not
            # kept once a run is done).
            done = 0
            for i, (_, steps) in enumerate(self.phases):
                if self.global_step < done + steps:
                    self.phase_index, self.phase_step = i, self.global_step - done
                    self.log(f"extending the finished run from step {self.global_step}")
                    break
                done += steps
        self._new_optimizer()
        if self.phase is not None and not finished:
            self.optimizer.load_state_dict(s["optimizer"])
            self.scaler.load_state_dict(s["scaler"])
        torch.set_rng_state(s["torch_rng"])

    def _keep_best(self, phase: str, metrics: dict) -> None:
        """Saves ``best.pt`` when ``metrics[select_metric]`` beats the best seen in the last phase."""
        metric = self.cfg.select_metric
        if phase != self.phases[-1][0] or metric not in metrics:
            return
        if self.best.get("phase") == phase and metrics[metric] <= self.best["value"]:
            return
        self.best = {"phase": phase, "metric": metric, "value": metrics[metric], "global_step": self.global_step}
        self.save("best.pt")
        self.log(f"best {metric} {metrics[metric]:.4f} at step {self.global_step}: best.pt")

    # -- the loop -----------------------------------------------------------------------------------------
    def _csv(self, row: dict) -> None:
        if not self.dist.is_main:
            return
        path = os.path.join(self.cfg.run_dir, "learning_curve.csv")
        fields = ["global_step", "phase", "phase_step", "train_loss", "val_loss", "val_psnr_amp", "val_psnr_fs",
                  "elapsed_s"]
        new = not os.path.exists(path)
        with open(path, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
            if new:
                w.writeheader()
            w.writerow(row)

    def _truncate_csv(self) -> None:
        """On resume, drop learning-curve rows written after the checkpoint's step."""
        path = os.path.join(self.cfg.run_dir, "learning_curve.csv")
        if not self.dist.is_main or not os.path.exists(path):
            return
        with open(path) as f:
            rows = list(csv.DictReader(f))
        if not rows:
            return
        fields = list(rows[0].keys())
        keep = [r for r in rows if int(r["global_step"]) <= self.global_step]
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=fields)
            w.writeheader()
            w.writerows(keep)

    def _batches(self):
        """Endless batches of this rank from the DataLoader (:class:`.data.ShardGroupedBatchSampler`): the
        batches of epoch ``e`` depend only on ``(seed, e, global batch)`` and the augmentation of item ``k``
        only on ``(seed, e, k)``, so a resumed run sees the same data; it starts inside the epoch of its
        global step."""
        epoch, pos = divmod(self.global_step, self.sampler.steps_per_epoch)
        while True:
            self.sampler.set_epoch(epoch, pos)
            yield from self.loader
            epoch, pos = epoch + 1, 0

    def run(self, max_steps: int | None = None) -> dict:
        """Runs (or resumes) all phases; returns the last validation metrics.

        Args:
            max_steps: stop (with a checkpoint) once ``global_step`` reaches this, as an interruption would;
                the next :meth:`run` resumes.
        """
        cfg = self.cfg
        ckpt = os.path.join(cfg.run_dir, "checkpoint.pt")
        if os.path.exists(ckpt):
            self.load(ckpt)
            self._truncate_csv()
            restarts = os.environ.get("TORCHELASTIC_RESTART_COUNT", "0")
            self.log(f"resumed from {ckpt} at step {self.global_step} ({self.phase or 'done'})"
                     + (f" after torchrun restart {restarts}" if restarts != "0" else ""))
        self.dist.barrier()  # every rank has read the checkpoint before rank 0 writes the next one
        config = cfg.to_dict() | {"training_commit": self.commit, "world_size": self.dist.world_size}
        if self.dist.is_main:
            with open(os.path.join(cfg.run_dir, "config.json"), "w") as f:
                json.dump(config, f, indent=1)
        self.log(f"device {self.device}, autocast {self.amp_dtype}, hologram CNN {cfg.num_layers} layers "
                 f"({count_parameters(self.net)} parameters)"
                 + (f", pre-filter {count_parameters(self.prefilter)} parameters" if self.prefilter else "")
                 + f", {len(self.train_set)} training scenes, phases {self.phases}"
                 + f"; world size {self.dist.world_size}, global batch {self.global_batch}, lr {self.base_lr:g}"
                 + f", {cfg.num_workers} DataLoader workers")
        t0 = time.time()
        metrics: dict = {}
        running, count = 0.0, 0
        batches = self._batches()
        while self.phase is not None:
            name, steps = self.phases[self.phase_index]
            if self.phase_step >= steps:
                if name == "stage1":
                    self.save("stage1.pt")
                self.phase_index += 1
                self.phase_step = 0
                self._new_optimizer()
                continue
            if max_steps is not None and self.global_step >= max_steps:
                self.save()
                self.log(f"stopped at step {self.global_step} (max_steps)")
                return metrics
            terms = self.train_step(next(batches))
            if not math.isfinite(terms["total"]):
                raise FloatingPointError(f"non-finite loss at step {self.global_step}: {terms}")
            self.phase_step += 1
            self.global_step += 1
            _inject_fault(self.dist.rank, self.global_step)
            running += terms["total"]
            count += 1
            last = self.phase_step == steps
            if self.global_step % cfg.log_every == 0 or last:
                msg = " ".join(f"{k} {v:.5f}" for k, v in terms.items())
                row = {"global_step": self.global_step, "phase": name, "phase_step": self.phase_step,
                       "train_loss": running / count, "elapsed_s": round(time.time() - t0, 2)}
                if (self.global_step % cfg.val_every == 0 or last) and self.dist.is_main:
                    metrics = self.validate(name)
                    row |= metrics
                    msg += " | " + " ".join(f"{k} {v:.4f}" for k, v in metrics.items())
                    self._keep_best(name, metrics)
                self.log(f"[{name} {self.phase_step}/{steps}] step {self.global_step} {msg}")
                self._csv(row)
                running, count = 0.0, 0
            if self.global_step % cfg.ckpt_every == 0 or last:
                self.save()
        self.save()
        self.save("final.pt")
        if self.dist.enabled:
            digests = [None] * self.dist.world_size
            torch.distributed.all_gather_object(digests, weights_digest(self.net, self.prefilter))
            self.log(f"weights sha256 per rank: {' '.join(digests)}"
                     + ("" if len(set(digests)) == 1 else "  (the ranks DIFFER)"))
        self.log(f"done in {time.time() - t0:.1f} s; checkpoints in {cfg.run_dir}")
        return metrics


def load_config(path: str | None, sets: list[str] | None = None, run_dir: str | None = None) -> TrainConfig:
    """Reads a JSON configuration (or the defaults when ``path`` is None) and applies ``key=value`` overrides."""
    cfg = TrainConfig()
    if path:
        with open(path) as f:
            cfg = TrainConfig.from_dict(json.load(f))
    for s in sets or []:
        cfg = set_option(cfg, s)
    if run_dir:
        cfg = dataclasses.replace(cfg, run_dir=run_dir)
    return cfg


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m tensorholo_training.train", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", help="JSON configuration (keys of TrainConfig); default: the small CPU run")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a configuration key (value parsed as JSON), repeatable")
    ap.add_argument("--run-dir", help="override run_dir")
    ap.add_argument("--print-config", action="store_true", help="print the resolved configuration and exit")
    ap.add_argument("--max-steps", type=int, help="stop (with a checkpoint) at this global step; rerun to resume")
    args = ap.parse_args(argv)
    cfg = load_config(args.config, args.set, args.run_dir)
    if args.print_config:
        print(json.dumps(cfg.to_dict(), indent=1))
        return 0
    trainer = Trainer(cfg, log=lambda m: print(m, flush=True))
    try:
        trainer.run(max_steps=args.max_steps)
    finally:
        if trainer.dist.enabled and torch.distributed.is_initialized():
            torch.distributed.destroy_process_group()
    if trainer.dist.enabled and __name__ == "__main__":
        # Every file is written and closed and the group is gone; leave without the interpreter's teardown.
        # Seen once in CI (torch gloo, 2 torchrun agents under Slurm): a c10d store thread destroyed while
        # joinable during teardown aborted a finished rank ("terminate called without an active exception",
        # exit -6), which torchrun counts as a failed worker: it restarts the group and waits for the other
        # agent, already gone, until the rendezvous times out.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
