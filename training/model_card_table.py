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
        f32 = None
        for suffix, label in (("", "f32"), (".int8-qop", "int8 QOperator"), (".int8-qdq", "int8 QDQ")):
            name = f"holo{layers}_rgbd{suffix}.json"
            if not os.path.exists(os.path.join(d, name)):
                continue
            m = load(name)["model"]["mean"]
            what = "CNN midpoint"
            if f32 is None:
                f32 = m
            else:
                what += f" (Δ vs f32: {m['psnr_amp'] - f32['psnr_amp']:+.2f} dB amp, " \
                        f"{m['psnr_fs'] - f32['psnr_fs']:+.2f} dB focal stack)"
            print(row(f"holo{layers} {label}", what, m))
        for o in (6, 12):
            aa = None
            name = f"holo{layers}_rgbd+aadpm_{o}mm.json"
            if os.path.exists(os.path.join(d, name)):
                aa = load(name)["model"]["mean"]
                print(row(f"holo{layers} f32 + AA-DPM {o} mm", "displayed (phase-only, AA-DPM)", aa))
            ddpm = None
            for suffix, label in (("", "f32"), (".int8-qop", "int8 QOperator"), (".int8-qdq", "int8 QDQ")):
                name = f"holo{layers}_rgbd+prefilter_{o}mm{suffix}.json"
                if not os.path.exists(os.path.join(d, name)):
                    continue
                m = load(name)["model"]["mean"]
                what = "displayed (phase-only, DDPM"
                if ddpm is None:
                    ddpm = m
                    if aa is not None:
                        what += f"; Δ vs AA-DPM: {m['psnr_amp'] - aa['psnr_amp']:+.2f} dB amp, " \
                                f"{m['psnr_fs'] - aa['psnr_fs']:+.2f} dB focal stack"
                else:
                    what += f"; Δ vs f32: {m['psnr_amp'] - ddpm['psnr_amp']:+.2f} dB amp, " \
                            f"{m['psnr_fs'] - ddpm['psnr_fs']:+.2f} dB focal stack"
                both = "" if suffix == "" else " (both CNNs int8)"
                print(row(f"holo{layers} {label} + pre-filter {o} mm{both}", what + ")", m))


if __name__ == "__main__":
    main()
