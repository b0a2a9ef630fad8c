#!/usr/bin/python3
"""Trains the learned tray detector (algo/include/agv/overhead/tray_net.hpp) on CPU and exports
it to ONNX for OpenCV's dnn module.

A small fully-convolutional one-stage detector in the role of Yang et al.'s YOLOv5-OBB: per output
cell (stride 8) an objectness, the centre's offset in the cell (2 sigmoid - 0.5, so a cell's
neighbours may carry a box, as YOLOv5), the box's length and width (exp times a 64 px anchor) and
the long axis's angle as (cos 2a, sin 2a), which a rectangle turned half a turn leaves unchanged.
The exported graph ends in those activations, so the C++ decoding is arithmetic only.

    /usr/bin/python3 tools/train/tray_obb/train.py --train DIR --test DIR --out models/tray_obb.onnx

DIR as make_tray_dataset writes it (crops/*.png, crops.csv, boxes.csv). README.md in this folder
has the whole recipe.
"""
import argparse
import csv
import math
import os
import random
import sys
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
from PIL import Image, ImageFilter

STRIDE = 8
ANCHOR_PX = 64.0


def conv(i, o, stride=1, dilation=1):
    return [nn.Conv2d(i, o, 3, stride, padding=dilation, dilation=dilation, bias=False),
            nn.BatchNorm2d(o), nn.ReLU(inplace=True)]


class TrayNet(nn.Module):
    """Receptive field about 135 px at stride 8: a 600 mm tray is 75 px at 8 mm per pixel.
    About 9 M multiply-adds per 128 x 128 window (35 M at 256 x 256)."""

    def __init__(self, width=24):
        super().__init__()
        self.body = nn.Sequential(
            *conv(1, 8, 2), *conv(8, 16, 2), *conv(16, 16), *conv(16, width, 2),
            *conv(width, width), *conv(width, width, dilation=2), *conv(width, width, dilation=4))
        self.obj = nn.Conv2d(width, 1, 1)
        self.off = nn.Conv2d(width, 2, 1)
        self.size = nn.Conv2d(width, 2, 1)
        self.ang = nn.Conv2d(width, 2, 1)
        nn.init.constant_(self.obj.bias, -4.0)

    def forward(self, x):
        f = self.body(x)
        return self.obj(f), self.off(f), self.size(f), self.ang(f)


class Exported(nn.Module):
    """The network with its output activations: 7 channels per cell as tray_net.cpp decodes."""

    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, x):
        o, off, size, ang = self.net(x)
        return torch.cat([torch.sigmoid(o), torch.sigmoid(off) * 2.0 - 0.5,
                          torch.exp(size) * ANCHOR_PX, ang], dim=1)


def load_set(folder):
    crops = list(csv.DictReader(open(os.path.join(folder, 'crops.csv'))))
    files = [c['file'] for c in crops]
    index = {f: i for i, f in enumerate(files)}
    images = np.stack([np.array(Image.open(os.path.join(folder, 'crops', f))) for f in files])
    boxes = [[] for _ in files]
    for r in csv.DictReader(open(os.path.join(folder, 'boxes.csv'))):
        boxes[index[r['file']]].append([float(r['cx']), float(r['cy']), float(r['length']),
                                        float(r['width']), float(r['angle_deg']), int(r['full'])])
    return images, boxes, crops


def standardise(img):
    """As tray_net.cpp: (x - mean) / max(sd, 8) over the window."""
    x = img.astype(np.float32)
    return (x - x.mean()) / max(float(x.std()), 8.0)


_GRIDS = {}


def unit_grid(n):
    """x and y across an n x n window, -0.5 .. 0.5."""
    if n not in _GRIDS:
        t = np.linspace(-0.5, 0.5, n, dtype=np.float32)
        _GRIDS[n] = (t[None, :].repeat(n, 0), t[:, None].repeat(n, 1))
    return _GRIDS[n]


def augment(img, boxes, rng):
    """A random symmetry of the square (flips and transpose); blur (a higher or poorer camera's
    coarser pixels); a light field (gain, a linear gradient and vignetting, darker than any
    rendered training frame); offset and noise after the gain (a dim frame's poorer signal)."""
    n = img.shape[0]
    b = [list(x) for x in boxes]
    if rng.random() < 0.5:
        img = img[:, ::-1]
        for x in b:
            x[0], x[4] = n - 1 - x[0], (180.0 - x[4]) % 180.0
    if rng.random() < 0.5:
        img = img[::-1, :]
        for x in b:
            x[1], x[4] = n - 1 - x[1], (-x[4]) % 180.0
    if rng.random() < 0.5:
        img = img.T
        for x in b:
            x[0], x[1], x[4] = x[1], x[0], (90.0 - x[4]) % 180.0
    if rng.random() < 0.5:
        im = Image.fromarray(np.ascontiguousarray(img))
        img = np.array(im.filter(ImageFilter.GaussianBlur(rng.uniform(0.3, 1.6))))
    f = img.astype(np.float32)
    if rng.random() < 0.7:
        xx, yy = unit_grid(n)
        a = rng.uniform(0.0, 2.0 * math.pi)
        field = 1.0 + rng.uniform(0.0, 0.6) * (math.cos(a) * xx + math.sin(a) * yy)
        field *= 1.0 - rng.uniform(0.0, 0.6) * (xx * xx + yy * yy)
        f *= field
    f = f * rng.uniform(0.35, 1.3) + rng.uniform(-30, 30)
    f += rng.standard_normal(f.shape, np.float32) * rng.uniform(0.0, 5.0)
    f = np.clip(f, 0, 255)
    return np.round(f) if rng.random() < 0.5 else f, b


def targets(boxes, n):
    """Per cell: positive mask, ignore mask, offsets (2), log size (2), cos 2a, sin 2a."""
    g = n // STRIDE
    pos = np.zeros((g, g), np.float32)
    ign = np.zeros((g, g), np.float32)
    reg = np.zeros((6, g, g), np.float32)
    for cx, cy, length, width, ang, full in boxes:
        px, py = (cx + 0.5) / STRIDE, (cy + 0.5) / STRIDE
        j, i = int(math.floor(px)), int(math.floor(py))
        if not full:
            ign[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2] = 1
            continue
        tx, ty = px - j, py - i
        cells = [(i, j), (i, j - 1 if tx < 0.5 else j + 1), (i - 1 if ty < 0.5 else i + 1, j)]
        a = math.radians(ang)
        for ci, cj in cells:
            if 0 <= ci < g and 0 <= cj < g:
                pos[ci, cj] = 1
                reg[:, ci, cj] = [px - cj, py - ci, math.log(length / ANCHOR_PX),
                                  math.log(width / ANCHOR_PX), math.cos(2 * a), math.sin(2 * a)]
        ign[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2] = 1
    ign[pos > 0] = 0
    return pos, ign, reg


def loss_fn(out, pos, ign, reg):
    o, off, size, ang = out
    o = o[:, 0]
    p = torch.sigmoid(o)
    bce = F.binary_cross_entropy_with_logits(o, pos, reduction='none')
    focal = bce * ((pos - p).abs() ** 2)
    npos = pos.sum().clamp(min=1.0)
    l_obj = (focal * (1 - ign)).sum() / npos
    m = pos > 0
    d_off = torch.sigmoid(off) * 2.0 - 0.5
    l_off = (d_off - reg[:, 0:2]).abs().permute(0, 2, 3, 1)[m].sum() / npos
    l_size = (size - reg[:, 2:4]).abs().permute(0, 2, 3, 1)[m].sum() / npos
    l_ang = (ang - reg[:, 4:6]).abs().permute(0, 2, 3, 1)[m].sum() / npos
    return l_obj + 5.0 * l_off + 2.0 * l_size + 4.0 * l_ang, (l_obj.item(), l_off.item())


def decode(out7, min_score=0.5):
    """Like decode_tray_output + a centre-distance suppression: boxes per image."""
    res = []
    for k in range(out7.shape[0]):
        o = out7[k]
        ii, jj = np.nonzero(o[0] >= min_score)
        cand = []
        for i, j in zip(ii, jj):
            a = 0.5 * math.atan2(o[6, i, j], o[5, i, j])
            cand.append([(j + o[1, i, j]) * STRIDE - 0.5, (i + o[2, i, j]) * STRIDE - 0.5,
                         o[3, i, j], o[4, i, j], math.degrees(a) % 180.0, o[0, i, j]])
        cand.sort(key=lambda c: -c[5])
        kept = []
        for c in cand:
            if all(math.hypot(c[0] - q[0], c[1] - q[1]) > 0.5 * min(c[3], q[3]) for q in kept):
                kept.append(c)
        res.append(kept)
    return res


def evaluate(model, images, boxes, match_px=7.5):
    """Recall and precision (a detection matches a full tray within match_px of its centre, 60 mm
    as eval_tray_net; a
    detection at a tray not wholly in the frame is neither), centre and angle errors."""
    exp = Exported(model).eval()
    tp = fp = fn = 0
    dc, da = [], []
    with torch.no_grad():
        for s in range(0, len(images), 128):
            x = torch.from_numpy(np.stack([standardise(im) for im in images[s:s + 128]])[:, None])
            dets = decode(exp(x).numpy())
            for k, d in enumerate(dets):
                truth = boxes[s + k]
                used = set()
                for c in d:
                    best, bi = 1e9, -1
                    for ti, t in enumerate(truth):
                        e = math.hypot(c[0] - t[0], c[1] - t[1])
                        if e < best and ti not in used:
                            best, bi = e, ti
                    if bi >= 0 and best <= match_px:
                        used.add(bi)
                        if truth[bi][5]:
                            tp += 1
                            dc.append(best)
                            e = abs(c[4] - truth[bi][4]) % 180.0
                            da.append(min(e, 180.0 - e))
                    else:
                        fp += 1
                fn += sum(1 for ti, t in enumerate(truth) if t[5] and ti not in used)
    rec = tp / max(tp + fn, 1)
    prec = tp / max(tp + fp, 1)
    pc = np.percentile(dc, [50, 95]) if dc else [0, 0]
    pa = np.percentile(da, [50, 95]) if da else [0, 0]
    return rec, prec, tp, fp, fn, pc, pa, float(np.std(dc)) if dc else 0.0


def export(model, path, input_px):
    exp = Exported(model).eval()
    x = torch.zeros(1, 1, input_px, input_px)
    torch.onnx.export(exp, x, path, opset_version=11, input_names=['window'],
                      output_names=['cells'], do_constant_folding=True)
    try:
        import onnx
        m = onnx.load(path)
        for k, v in (('agv.mm_per_px', '8'), ('agv.stride_px', str(STRIDE)),
                     ('agv.input', 'gray window standardised: (x - mean) / max(sd, 8)')):
            e = m.metadata_props.add()
            e.key, e.value = k, v
        onnx.checker.check_model(m)
        onnx.save(m, path)
    except ImportError:
        print('python3-onnx not installed: metadata not added', file=sys.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--train', required=True, nargs='+', help='one or more dataset folders')
    ap.add_argument('--test', required=True)
    ap.add_argument('--out', required=True)
    ap.add_argument('--epochs', type=int, default=40)
    ap.add_argument('--batch', type=int, default=32)
    ap.add_argument('--lr', type=float, default=3e-3)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--threads', type=int, default=1,
                    help='1: several OpenMP threads on a busy machine are far slower')
    ap.add_argument('--max-minutes', type=float, default=14.0)
    ap.add_argument('--input-px', type=int, default=256, help='the exported model\'s window')
    ap.add_argument('--width', type=int, default=24,
                    help='channels of the last four layers (compute grows about as its square)')
    a = ap.parse_args()
    torch.manual_seed(a.seed)
    np.random.seed(a.seed)
    random.seed(a.seed)
    torch.set_num_threads(a.threads)
    rng = np.random.default_rng(a.seed)
    sets = [load_set(d) for d in a.train]
    tr_img = np.concatenate([x[0] for x in sets])
    tr_box = [b for x in sets for b in x[1]]
    te_img, te_box, _ = load_set(a.test)
    n = tr_img.shape[1]
    print(f'train {len(tr_img)} crops, test {len(te_img)} crops of {n} px', flush=True)
    model = TrayNet(a.width)
    opt = torch.optim.AdamW(model.parameters(), lr=a.lr, weight_decay=1e-4)
    steps = a.epochs * (len(tr_img) // a.batch)
    budget_s = 60.0 * a.max_minutes

    def lr_at(step, elapsed_s):
        # Warm-up, then a cosine to zero over whichever ends first, the epochs or the time
        # budget: a run cut short by the budget still ends annealed.
        done = max(step / steps, elapsed_s / budget_s)
        if step < 0.03 * steps:
            return a.lr * (0.1 + 0.9 * step / (0.03 * steps))
        return 0.5 * a.lr * (1.0 + math.cos(math.pi * min(done, 1.0)))

    t0 = time.time()
    step = 0
    for ep in range(a.epochs):
        model.train()
        order = rng.permutation(len(tr_img))
        tot = 0.0
        for s in range(0, len(order) - a.batch + 1, a.batch):
            if time.time() - t0 >= budget_s:
                break
            xs, ps, gs, rs = [], [], [], []
            for k in order[s:s + a.batch]:
                img, b = augment(tr_img[k], tr_box[k], rng)
                p, g, r = targets(b, n)
                xs.append(standardise(img))
                ps.append(p)
                gs.append(g)
                rs.append(r)
            out = model(torch.from_numpy(np.stack(xs)[:, None]))
            loss, _ = loss_fn(out, torch.from_numpy(np.stack(ps)), torch.from_numpy(np.stack(gs)),
                              torch.from_numpy(np.stack(rs)))
            for grp in opt.param_groups:
                grp['lr'] = lr_at(step, time.time() - t0)
            opt.zero_grad()
            loss.backward()
            opt.step()
            step += 1
            tot += loss.item()
        last = ep + 1 == a.epochs or time.time() - t0 >= budget_s
        if (ep + 1) % 5 and not last:
            print(f'epoch {ep + 1}: loss {tot / max(len(order) // a.batch, 1):.3f}; '
                  f'{(time.time() - t0) / 60:.1f} min', flush=True)
            continue
        model.eval()
        rec, prec, tp, fp, fn, pc, pa, _ = evaluate(model, te_img, te_box)
        print(f'epoch {ep + 1}: loss {tot / max(len(order) // a.batch, 1):.3f}; test recall '
              f'{rec:.4f} precision {prec:.4f} (tp {tp} fp {fp} fn {fn}); centre p50/p95 '
              f'{pc[0]:.2f}/{pc[1]:.2f} px, angle p50/p95 {pa[0]:.2f}/{pa[1]:.2f} deg; '
              f'{(time.time() - t0) / 60:.1f} min', flush=True)
        if last and ep + 1 < a.epochs:
            print('time limit reached', flush=True)
            break
    export(model, a.out, a.input_px)
    print(f'wrote {a.out} ({os.path.getsize(a.out)} bytes)')


if __name__ == '__main__':
    main()
