"""python review/crop6.py x0,y0,x1,y1 A.exr [B.exr ...] [OUT.png]: each image's mean over the crop (rows from the
top); with OUT.png the crops side by side, 6x, sRGB clipped."""
import numpy as np
import sys
import OpenImageIO as oiio
x0, y0, x1, y1 = map(int, sys.argv[1].split(","))
pngs = [a for a in sys.argv[2:] if a.endswith(".png")]
tiles = []
for path in [a for a in sys.argv[2:] if not a.endswith(".png")]:
    px = oiio.ImageBuf(path).get_pixels(oiio.FLOAT)[..., :3]
    print(f"{path}: crop {px[y0:y1, x0:x1].mean(axis=(0, 1)).round(4)} image {px.mean(axis=(0, 1)).round(4)}")
    c = np.clip(np.nan_to_num(px[y0:y1, x0:x1]), 0, 1)
    c = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    tiles += [np.repeat(np.repeat(c, 6, 0), 6, 1), np.ones((6 * (y1 - y0), 6, 3))]
if pngs:
    img = np.concatenate(tiles[:-1], 1)
    o = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], 3, "uint8"))
    o.set_pixels(oiio.ROI(), (img * 255 + 0.5).astype(np.uint8)); o.write(pngs[0])
