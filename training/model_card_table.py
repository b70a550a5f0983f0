"""Prints the model card's quality table (Markdown) from the Table 2 reports in ``models/eval/``
(``training/ship_cpu.sh eval`` and the baselines evaluation, see ``models/MODEL_CARD.md``).

    python training/model_card_table.py [models/eval]
"""
import json
import os
import sys


def row(name, what, m):
    return (f"| {name} | {what} | {m['psnr_amp']:.2f} | {m['ssim_amp']:.3f} | {m['psnr_fs']:.2f} | "
            f"{m['ssim_fs']:.3f} |")


def main() -> None:
    d = sys.argv[1] if len(sys.argv) > 1 else "models/eval"
    load = lambda n: json.load(open(os.path.join(d, n)))  # noqa: E731
    print("| model / method | what is scored | amplitude PSNR (dB) | amplitude SSIM | focal stack PSNR (dB) "
          "| focal stack SSIM |")
    print("|---|---|---:|---:|---:|---:|")
    if os.path.exists(os.path.join(d, "baselines.json")):
        b = load("baselines.json")
        for key, label in [("maimone", "Maimone-style layer-based (RGB-D, no occlusion handling)"),
                           ("smlbm-aadpm-0mm", "SM-LBM (RGB-D) + AA-DPM, 0 mm"),
                           ("smlbm-aadpm-6mm", "SM-LBM (RGB-D) + AA-DPM, 6 mm"),
                           ("smlbm-aadpm-12mm", "SM-LBM (RGB-D) + AA-DPM, 12 mm")]:
            if key in b:
                what = "complex midpoint" if key == "maimone" else "displayed (phase-only)"
                print(row(label, what, b[key]["mean"]))
    for layers in (8, 15, 30):
        for m, label, delta in precisions(d, f"holo{layers}_rgbd{{}}.json", "f32"):
            what = "CNN midpoint" + (f" ({delta})" if delta else "")
            print(row(f"holo{layers} {label}", what, m))
        for o in (6, 12):
            aa = None
            name = f"holo{layers}_rgbd+aadpm_{o}mm.json"
            if os.path.exists(os.path.join(d, name)):
                aa = load(name)["model"]["mean"]
                print(row(f"holo{layers} f32 + AA-DPM {o} mm", "displayed (phase-only, AA-DPM)", aa))
            for m, label, delta in precisions(d, f"holo{layers}_rgbd+prefilter_{o}mm{{}}.json", "f32"):
                if not delta and aa is not None:
                    delta = difference(m, aa, "AA-DPM")
                both = " (both CNNs int8; pre-filter mixed precision)" if label != "f32" else ""
                print(row(f"holo{layers} {label} + pre-filter {o} mm{both}", "displayed (phase-only, DDPM"
                          + (f"; {delta}" if delta else "") + ")", m))


def difference(m: dict, ref: dict, name: str) -> str:
    """``Δ vs NAME: … dB amp, … dB focal stack``."""
    return (f"Δ vs {name}: {m['psnr_amp'] - ref['psnr_amp']:+.2f} dB amp, "
            f"{m['psnr_fs'] - ref['psnr_fs']:+.2f} dB focal stack")


def precisions(d: str, pattern: str, first: str):
    """``(mean metrics, precision label, Δ vs the f32 report or "")`` for the f32, int8 QOperator and QDQ
    reports ``pattern.format(suffix)`` that exist in ``d``."""
    f32 = None
    for suffix, label in (("", first), (".int8-qop", "int8 QOperator"), (".int8-qdq", "int8 QDQ")):
        path = os.path.join(d, pattern.format(suffix))
        if not os.path.exists(path):
            continue
        m = json.load(open(path))["model"]["mean"]
        delta = "" if f32 is None else difference(m, f32, "f32")
        f32 = f32 or m
        yield m, label, delta


if __name__ == "__main__":
    main()
