"""The figure of docs/REFINE.md "Through a display model": a simulated display with hidden parameters
(`holo calibrate model simulate`, 128 x 128, three colours), the model fitted from its captures
(`holo calibrate model fit`), the built-in scene refined 10 iterations through the ideal display and through
the fitted model (`holo render --refine 10 [--display-model]`), and both sets of codes as the *simulated*
display shows them, focused near and far (`cargo run --release -p tensorholo --example display_model_view`).

Usage: python benchmarks/display_model_figure.py OUT.jpg [WORK_DIR]   (holo and the example built in release)
"""
import os
import subprocess
import sys

from PIL import Image, ImageDraw

root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
holo = os.path.join(root, "target", "release", "holo")
view = os.path.join(root, "target", "release", "examples", "display_model_view")
out = sys.argv[1]
work = sys.argv[2] if len(sys.argv) > 2 else "display-model-figure"
os.makedirs(work, exist_ok=True)
run = lambda *a: subprocess.run(a, check=True, cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
run(holo, "calibrate", "model", "simulate", "--size", "128x128", "--colours", "red,green,blue", "--out", "sim")
run(holo, "calibrate", "model", "fit", "--captures", "sim/manifest.json", "--out", "fitted.json")
run(holo, "render", "--size", "128x128", "--refine", "10", "--out", "ideal")
run(holo, "render", "--size", "128x128", "--refine", "10", "--display-model", "fitted.json", "--out", "fitted")
rows, depths, side = [("ideal", "refined through the ideal display"), ("fitted", "refined through the fitted model")], ["0.25", "0.75"], 256
fig = Image.new("RGB", (2 * side + 10, 2 * (side + 22) + 4), "white")
draw = ImageDraw.Draw(fig)
for i, (name, label) in enumerate(rows):
    y = i * (side + 22)
    draw.text((4, y + 4), f"{label}, shown by the simulated display: focused at d = 0.25 | d = 0.75", fill="black")
    for j, d in enumerate(depths):
        png = os.path.join(work, f"view_{name}_{d}.png")
        run(view, "sim/hidden.json", name, d, os.path.abspath(png))
        fig.paste(Image.open(png).convert("RGB").resize((side, side), Image.NEAREST), (j * (side + 10), y + 20))
fig.save(out, quality=88)
