#!/usr/bin/env python3
"""Writes a copy of a rack drive recording's REC/ranging.yaml and ranging_site.yaml whose wall
landmarks sit where the site renderer prints them: 1 mm proud of the face, along the facing
(site_render_faces.cpp keeps the print in front of its face for the depth test), where the
written map has them on the face itself. A diagnostic for rack_drive_eval.sh (docs/design/
ranging.md, "Drive evaluation"): replayed with the returned configuration, the map-versus-print
offset, an error common to every frame of a face, is gone.

Usage: map_at_print.py REC OUT_DIR   (prints the path of the configuration to pass to replay)
"""
import math
import os
import re
import sys

PROUD_MM = 1.0


def shift(line):
    x = float(re.search(r"\bx_mm: ([-\d.]+)", line).group(1))
    y = float(re.search(r"\by_mm: ([-\d.]+)", line).group(1))
    facing = math.radians(float(re.search(r"facing_deg: ([-\d.]+)", line).group(1)))
    x += PROUD_MM * math.cos(facing)
    y += PROUD_MM * math.sin(facing)
    line = re.sub(r"\bx_mm: [-\d.]+", f"x_mm: {x:.3f}", line, count=1)
    return re.sub(r"\by_mm: [-\d.]+", f"y_mm: {y:.3f}", line, count=1)


def main(argv):
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    rec, out = argv
    os.makedirs(out, exist_ok=True)
    site = open(os.path.join(rec, "ranging_site.yaml")).read()
    site = re.sub(r"  - \{id: \d+, family:.*\}", lambda m: shift(m.group(0)), site)
    site_path = os.path.abspath(os.path.join(out, "ranging_site_at_print.yaml"))
    open(site_path, "w").write(site)
    cfg = open(os.path.join(rec, "ranging.yaml")).read()
    cfg = cfg.replace("site: ranging_site.yaml", f"site: {site_path}")
    cfg_path = os.path.join(out, "ranging_at_print.yaml")
    open(cfg_path, "w").write(cfg)
    print(cfg_path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
