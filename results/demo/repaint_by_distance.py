# Where a model changes the background: the share of the pixels outside the head that differ
# from bc.png by more than 1.5/255, by distance from the head mask, over a run's val renders.
# Usage: python repaint_by_distance.py RUN [STUDENT [EVAL]]  (needs numpy, scipy, pillow);
# STUDENT is the student's folder (default student), EVAL the evaluation folder (RUN/eval).
import numpy as np, glob, os, sys
from PIL import Image
from scipy import ndimage
root = sys.argv[1]
label = sys.argv[2] if len(sys.argv) > 2 else "student"
ev = sys.argv[3] if len(sys.argv) > 3 else f"{root}/eval"
bg = np.asarray(Image.open(f"{root}/data/bc.png").convert("RGB")).astype(np.float32)
H, W = bg.shape[:2]
ids = sorted(int(os.path.basename(p)[:-4]) for p in glob.glob(f"{ev}/val/{label}/*.png"))
hist = {"teacher": np.zeros(12), label: np.zeros(12)}
mag = {"teacher": [], label: []}
total_out = 0
for i in ids:
    par = np.asarray(Image.open(f"{root}/data/parsing/{i}.png").convert("RGB")).astype(int)
    head = (par[..., 2] > 200) & (par[..., 0] < 60) & (par[..., 1] < 60)
    if head.sum() == 0:  # nldf's own label file
        reg = np.asarray(Image.open(f"{root}/data/regions/{i}.png").convert("RGB")).astype(int)
        head = np.abs(reg - reg[0, 0]).sum(-1) > 0
    dist = ndimage.distance_transform_edt(~head)  # pixels from the head
    out = ~head
    total_out += out.sum()
    for m in hist:
        img = np.asarray(Image.open(f"{ev}/val/{m}/{i}.png").convert("RGB")).astype(np.float32)
        diff = np.abs(img - bg).max(-1)
        changed = (diff > 1.5) & out
        d = np.clip(dist[changed], 0, 11.99).astype(int)
        hist[m] += np.bincount(d, minlength=12)[:12]
        mag[m].extend(diff[changed].tolist())
n = len(ids)
print(root, n, "frames; share of the outside pixels repainted:",
      ", ".join(f"{m} {100 * hist[m].sum() / total_out:.2f} %" for m in hist))
print("by distance from the head (px): 0-1, 1-2, ..., 11+ (share of outside pixels, %)")
for m in hist:
    print(" ", m, " ".join(f"{100*v/total_out:.2f}" for v in hist[m]))
for m in mag:
    a = np.array(mag[m]); print(" ", m, "repaint size (/255): median %.1f, 90th %.1f" % (np.median(a), np.percentile(a, 90)))
