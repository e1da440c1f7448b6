"""python compare.py A.exr B.exr OUT.png : means, ratios, side-by-side PNG (sRGB, clipped)."""
import sys, numpy as np, OpenImageIO as oiio
def read(p):
    b = oiio.ImageBuf(p); spec = b.spec(); names = list(spec.channelnames)
    a = b.get_pixels(oiio.FLOAT)
    for pre in ("ViewLayer.Combined.", "RenderLayer.Combined.", "Combined.", ""):
        if pre + "R" in names:
            return a[..., [names.index(pre + c) for c in "RGB"]]
    return a[..., :3]
a, b = read(sys.argv[1]), read(sys.argv[2])
expo = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
print("mean A", a.mean(axis=(0, 1)), "mean B", b.mean(axis=(0, 1)), "ratio A/B", a.mean() / b.mean())
h, w = a.shape[:2]
for name, sl in (("top", np.s_[:h//2]), ("bottom", np.s_[h//2:]), ("left", np.s_[:, :w//2]), ("right", np.s_[:, w//2:])):
    print(f"  {name}: A/B {a[sl].mean()/max(b[sl].mean(),1e-9):.3f}")
def srgb(x):
    x = np.clip(np.nan_to_num(x), 0, 1); return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
gh, gw = 4, 4
for i in range(gh):
    print("  grid A/B", " ".join(f"{a[i*h//gh:(i+1)*h//gh, j*w//gw:(j+1)*w//gw].mean()/max(b[i*h//gh:(i+1)*h//gh, j*w//gw:(j+1)*w//gw].mean(),1e-9):6.3f}" for j in range(gw)))
img = np.concatenate([srgb(a*expo), np.ones((h, 4, 3)), srgb(b*expo)], 1)
img = np.repeat(np.repeat(img, 3, 0), 3, 1)
o = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], 3, "uint8")); o.set_pixels(oiio.ROI(), (img * 255 + 0.5).astype(np.uint8)); o.write(sys.argv[3])
