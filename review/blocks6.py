"""python review/blocks6.py REF.exr A.exr [B.exr ...]: each image / REF by 16 x 15 pixel blocks (luminance),
the image mean ratio and the share of blocks off by more than 5 % and 10 %."""
import sys
import numpy as np
import OpenImageIO as oiio


def lum(path):
    px = oiio.ImageBuf(path).get_pixels(oiio.FLOAT)[..., :3]
    return px @ np.array([0.2126, 0.7152, 0.0722])


ref = lum(sys.argv[1]); h, w = ref.shape; bh, bw = 15, 16
blocks = lambda a: a[:h // bh * bh, :w // bw * bw].reshape(h // bh, bh, w // bw, bw).mean(axis=(1, 3))
rb = blocks(ref)
for path in sys.argv[2:]:
    q = blocks(lum(path)) / rb
    print(f"{path}: mean {lum(path).mean() / ref.mean():.4f}; blocks {q.min():.3f}-{q.max():.3f}, "
          f"|1-q| > 5 %: {np.mean(abs(q - 1) > 0.05):.0%}, > 10 %: {np.mean(abs(q - 1) > 0.10):.0%}")
    for row in q:
        print("   ", " ".join(f"{v:5.2f}" for v in row))
