"""python ratio_map.py REF.exr TEST.exr OUT.png [BLOCK]: the TEST / REF ratio of BLOCK x BLOCK block means
(mean of RGB), blue (0.8) - white (1) - red (1.2), next to REF and TEST (sRGB of clip(x, 0, 1)), x3.
Prints the blocks furthest from 1."""
import sys, numpy as np, OpenImageIO as oiio

def read(p):
    inp = oiio.ImageInput.open(p); sub = 0; ch = {}
    while inp.seek_subimage(sub, 0):
        sp = inp.spec(); px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, -1)
        for c, n in enumerate(sp.channelnames): ch[n] = px[..., c]
        sub += 1
    for pre in ("ViewLayer.Combined.", "Combined.", ""):
        if pre + "R" in ch: return np.stack([ch[pre + c] for c in "RGB"], -1).astype(np.float64)

def srgb(x):
    x = np.clip(np.nan_to_num(x), 0, 1); return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)

ref, test, out = read(sys.argv[1]), read(sys.argv[2]), sys.argv[3]
B = int(sys.argv[4]) if len(sys.argv) > 4 else 10
H, W = ref.shape[:2]; h, w = H // B, W // B
blk = lambda x: x[:h * B, :w * B].mean(-1).reshape(h, B, w, B).mean((1, 3))
r = blk(test) / np.maximum(blk(ref), 1e-6)
t = np.clip((r - 1) / 0.2, -1, 1)
col = np.stack([1 - np.maximum(-t, 0), 1 - np.abs(t), 1 - np.maximum(t, 0)], -1)
col = np.repeat(np.repeat(col, B, 0), B, 1)
pad = np.zeros((H, W, 3)); pad[:h * B, :w * B] = col
row = np.concatenate([srgb(ref), np.ones((H, 2, 3)), srgb(test), np.ones((H, 2, 3)), pad], 1)
row = np.repeat(np.repeat(row, 3, 0), 3, 1)
o = oiio.ImageBuf(oiio.ImageSpec(row.shape[1], row.shape[0], 3, "uint8")); o.set_pixels(oiio.ROI(), (row * 255 + 0.5).astype(np.uint8)); o.write(out)
idx = np.argsort(-np.abs(r - 1).ravel())[:6]
print("worst blocks (row, col, ratio, ref level):", [(int(i // w), int(i % w), round(float(r.ravel()[i]), 3), round(float(blk(ref).ravel()[i]), 4)) for i in idx])
