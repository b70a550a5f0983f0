"""PyTorch training for tensorholo (Tensor Holography V2, Shi, Li & Matusik 2022).

Modules:

- :mod:`.optics`   differentiable copies of the SDK's physics (ASM, offset propagation, double phase, Fourier
  filter, focal stacks), checked against fixtures written by ``holo``;
- :mod:`.model`    hologram CNN (8/15/30 layers) and the DDPM pre-filter CNN;
- :mod:`.data`     reader of the LDI dataset written by ``holo dataset``;
- :mod:`.losses`   stage-1 and stage-2 losses (data fidelity, dynamic focal stack, Eq. 11 regulariser);
- :mod:`.train`    two-stage training CLI; :mod:`.export` ONNX export and int8 quantisation;
- :mod:`.evaluate` the paper's Table 2 protocol; :mod:`.metrics` PSNR and SSIM.

Conventions are those of the SDK (``docs/CONVENTIONS.md``): SI units, channel order R, G, B, normalised depth 0 = near,
``z(d) = (0.5 − d)·volume_depth``.
"""

__version__ = "0.1.0"
