"""python compare_flip.py REF.exr TEST.exr [TEST2.exr ...] [--png OUT.png] [--expo E]

Per test image against the reference (Combined, linear): mean ratio, 3x3 grid of mean ratios,
LDR-FLIP after the Standard view (sRGB curve of clip(x, 0, 1)), the share of pixels whose FLIP > 0.2,
the fraction of 'firefly' pixels (> 10x their 5x5 neighbourhood median).  --png writes the images side
by side (reference first, each x3).  --expo E scales both images first (FLIP and PNG; ratios unchanged)."""
import sys, numpy as np, OpenImageIO as oiio
import flip_evaluator as flip
from scipy.ndimage import median_filter

def read(p):
    inp = oiio.ImageInput.open(p); sub = 0; chans = {}
    while inp.seek_subimage(sub, 0):
        sp = inp.spec(); px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, sp.nchannels)
        for c, n in enumerate(sp.channelnames): chans[n] = px[..., c]
        sub += 1
    for pre in ("ViewLayer.Combined.", "RenderLayer.Combined.", "Combined.", ""):
        if pre + "R" in chans:
            return np.stack([chans[pre + c] for c in "RGB"], -1).astype(np.float64)
    raise SystemExit(f"{p}: no Combined")

def srgb(x):
    x = np.clip(np.nan_to_num(x), 0, 1); return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)

args = sys.argv[1:]; png = expo = None
if "--png" in args: i = args.index("--png"); png = args[i + 1]; del args[i:i + 2]
if "--expo" in args: i = args.index("--expo"); expo = float(args[i + 1]); del args[i:i + 2]
scale = expo or 1.0                    # exposure applied to both before FLIP and the PNG (ratios unchanged)
ref = read(args[0]) * scale; H, W = ref.shape[:2]
imgs = [ref]
for p in args[1:]:
    x = read(p) * scale; imgs.append(x)
    _, fmean, _ = flip.evaluate(np.ascontiguousarray(srgb(ref), np.float32), np.ascontiguousarray(srgb(x), np.float32), "LDR", inputsRGB=True, applyMagma=False)
    fmap = np.asarray(flip.evaluate(np.ascontiguousarray(srgb(ref), np.float32), np.ascontiguousarray(srgb(x), np.float32), "LDR", inputsRGB=True, applyMagma=False)[0]).reshape(H, W)
    y = x.mean(-1); fire = float(np.mean(y > 10 * np.maximum(median_filter(y, 5), 1e-4)))
    yr = ref.mean(-1); fire_ref = float(np.mean(yr > 10 * np.maximum(median_filter(yr, 5), 1e-4)))
    print(f"{p}: mean ratio {x.mean() / ref.mean():.4f} (R G B {x[..., 0].mean() / ref[..., 0].mean():.3f} {x[..., 1].mean() / ref[..., 1].mean():.3f} {x[..., 2].mean() / ref[..., 2].mean():.3f}), LDR-FLIP {fmean:.4f}, FLIP>0.2 {np.mean(fmap > 0.2):.3f}, fireflies {fire:.4f} (ref {fire_ref:.4f})")
    for i in range(3):
        print("   grid", " ".join(f"{x[i*H//3:(i+1)*H//3, j*W//3:(j+1)*W//3].mean() / max(ref[i*H//3:(i+1)*H//3, j*W//3:(j+1)*W//3].mean(), 1e-9):6.3f}" for j in range(3)))
if png:
    row = np.concatenate(sum([[srgb(im), np.ones((H, 3, 3))] for im in imgs], [])[:-1], 1)
    row = np.repeat(np.repeat(row, 3, 0), 3, 1)
    o = oiio.ImageBuf(oiio.ImageSpec(row.shape[1], row.shape[0], 3, "uint8")); o.set_pixels(oiio.ROI(), (row * 255 + 0.5).astype(np.uint8)); o.write(png)
