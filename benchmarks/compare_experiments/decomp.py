"""Bias / variance decomposition over seeds, per image region.  usage: decomp.py WxH tag:json ..."""
from common import *
import json, hashlib
OUT = os.path.join(WORK, "cache"); os.makedirs(OUT, exist_ok=True)

def cached(res, seed, kw):
    key = hashlib.sha1(json.dumps([res, seed, kw], sort_keys=True).encode()).hexdigest()[:16]
    p = f"{OUT}/{key}.npz"
    if os.path.exists(p):
        d = np.load(p); return d["rgb"], float(d["wall"])
    sc = moving_caustic_scene(res)
    rgb, w, _ = run(sc, seed=seed, **kw)
    np.savez(p, rgb=rgb, wall=w); return rgb, w

def regions(ex):
    L = ex[..., 0]
    gy, gx = np.gradient(L)
    g = np.hypot(gx, gy)
    H, W = L.shape
    x = -1.2 + (np.arange(W) + 0.5) * 2.4 / W
    y = 0.8 - (np.arange(H) + 0.5) * 2.4 / W
    X, Y = np.meshgrid(x, y)
    edge = g > 0.25 * np.percentile(g, 99)
    # box footprint swept (|y|<0.3+pad, box covers x in [-1.1, 1.1]); box edges at |y| = 0.3 and x-edges
    boxy = (np.abs(np.abs(Y) - 0.3) < 0.06) & (np.abs(X) < 1.15)
    # caustic leading/trailing edges at the shutter ends: caustic x-range on floor = 3*(c +- 0.3), c in [-0.25, 0.25]
    ends = (np.abs(X - 3 * (-0.25 - 0.3)) < 0.12) | (np.abs(X - 3 * (0.25 + 0.3)) < 0.12) | \
           (np.abs(X - 3 * (-0.25 + 0.3)) < 0.12) | (np.abs(X - 3 * (0.25 - 0.3)) < 0.12)
    ends &= np.abs(Y) < 0.95
    flat = ~edge & ~boxy & ~ends & (L > 0.05)
    dark = (L <= 0.05) & ~edge
    return {"edge": edge, "box_y_edges": boxy, "caustic_end_x": ends, "flat_lit": flat, "dark": dark}

def decompose(res, kw, seeds):
    ex = exact(res)
    imgs, walls = zip(*(cached(res, s, kw) for s in seeds))
    imgs = np.array(imgs); n = len(seeds)
    mean = imgs.mean(0)
    var = imgs.var(0, ddof=1)                          # per-pixel variance of one render
    bias2 = (mean - ex) ** 2 - var / n                 # unbiased estimate of squared bias
    mse = ((imgs - ex) ** 2).mean(0)
    out = {"wall": float(np.median(walls)), "rmse": float(np.sqrt(mse.mean())),
           "var": float(var.mean()), "bias2": float(bias2.mean()),
           "mean_rel": float((mean - ex).mean() / ex.mean())}
    w = 1.0 / (ex * ex + 0.01)
    out["relmse"] = float((mse * w).mean()); out["rel_var"] = float((var * w).mean()); out["rel_bias2"] = float((bias2 * w).mean())
    tot = mse.sum()
    for name, m in regions(ex).items():
        out[f"{name}:frac_px"] = float(m.mean())
        out[f"{name}:mse_share"] = float(mse[m].sum() / tot)
        out[f"{name}:var"] = float(var[m].mean()); out[f"{name}:bias2"] = float(bias2[m].mean())
    return out

if __name__ == "__main__":
    W, H = map(int, sys.argv[1].split("x")); res = (W, H)
    seeds = [int(s) for s in sys.argv[2].split(",")]
    for spec in sys.argv[3:]:
        tag, js = spec.split("=", 1)
        kw = json.loads(js)
        o = decompose(res, kw, seeds)
        print(json.dumps({"res": sys.argv[1], "tag": tag, **{k: (round(v, 7) if isinstance(v, float) else v) for k, v in o.items()}}), flush=True)
