#!/usr/bin/env python3
"""Writes the seed corpus of every harness (fuzz/corpus/<harness>/) deterministically.

Seeds are small valid inputs of each surface plus a few near misses; libFuzzer grows the corpus
from them. Rerun after changing a format: python3 fuzz/make_seeds.py [CORPUS_DIR]

The corpus also holds inputs this script does not write: minimised finds of past campaigns
(fuzz_vision's hashes) and regression inputs (regress_*). Those are kept. The script owns only
the files listed in CORPUS_DIR/seeds.manifest (harness/name per line, written on every run): a
seed it no longer writes is removed, every other file is left alone. Removing a minimised input
is a decision for a person (git rm), not a side effect of regenerating the seeds.
"""
import os
import sys
import struct
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORPUS = os.path.join(ROOT, "fuzz", "corpus")
MANIFEST = "seeds.manifest"
_written = []


def put(harness, name, data):
    _written.append(f"{harness}/{name}")
    d = os.path.join(CORPUS, harness)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def png(width, height, color_type, bit_depth, rows, interlace=0, extra=b""):
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(
            ">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, interlace)
    raw = b"".join(b"\0" + r for r in rows)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + extra +
            chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def read_manifest(corpus):
    try:
        with open(os.path.join(corpus, MANIFEST), encoding="utf-8") as f:
            return [line.strip() for line in f if line.strip() and not line.startswith("#")]
    except FileNotFoundError:
        return []


def main():
    global CORPUS
    if len(sys.argv) > 1:
        CORPUS = os.path.abspath(sys.argv[1])
    owned_before = read_manifest(CORPUS)
    _written.clear()
    write_seeds()
    if len(set(_written)) != len(_written):
        sys.exit("make_seeds.py: a seed name is written twice")
    for rel in sorted(set(owned_before) - set(_written)):
        # Only a plain harness/name under the corpus: a manifest edited by hand must not reach out.
        parts = rel.split("/")
        if len(parts) == 2 and all(p and p not in (".", "..") for p in parts):
            path = os.path.join(CORPUS, *parts)
            if os.path.isfile(path):
                os.remove(path)
                print(f"make_seeds.py: removed the stale seed {rel}")
    with open(os.path.join(CORPUS, MANIFEST), "w", encoding="utf-8") as f:
        f.write("# Written by fuzz/make_seeds.py: the seeds it owns (it removes one it no longer\n"
                "# writes). Every other file under fuzz/corpus/ is a kept input (minimised finds,\n"
                "# regressions) that the script never touches.\n")
        f.writelines(f"{rel}\n" for rel in sorted(_written))


def write_seeds():
    # QR payload: both forms, the extremes of every field, near misses.
    for i, s in enumerate(["AGV1/00017/+001000.0/-002000.0/+090.00", "AGV1/65535/MAP",
                           "AGV1/00001/-999999.9/+999999.9/+180.00",
                           "AGV1/00002/+000000.0/-000000.0/-179.99", "AGV1/00000/MAP",
                           "AGV2/00017/MAP", "AGV1/00017/+001000.0/-002000.0/-180.00"]):
        put("fuzz_payload", f"seed{i}", s)
    # Landmark map: the shipped grid, comments, CRLF, duplicates.
    with open(os.path.join(ROOT, "tools", "maps", "default_grid.csv"), "rb") as f:
        put("fuzz_map", "default_grid", f.read())
    put("fuzz_map", "small", "# c\n\nid,x_mm,y_mm,heading_deg\r\n17, +1000.5 ,-2000,90\n18,0,0,-179.996\n")
    put("fuzz_map", "dup", "id,x_mm,y_mm,heading_deg\n1,0,0,0\n1,0,0,0\n")
    put("fuzz_map", "range", "id,x_mm,y_mm,heading_deg\n65535,999999.9,-999999.9,180\n")
    # Recording files (docs/guide/recording.md).
    meta = """# agvloc recording metadata, docs/guide/recording.md
format_version: 1
source: "agvloc-desk sim --out rec \\"q\\""
image:
  width_px: 640
  height_px: 480
intrinsics:
  fx: 769.23076923076917
  fy: 769.23076923076917
  cx: 319.5
  cy: 239.5
distortion:
  k1: -0.21
  k2: 0.05
  p1: 0.001
  p2: -0.0007
  k3: 0
mount:
  height_mm: 200
  offset_x_mm: 35.5
  offset_y_mm: -12.25
  yaw_deg: 180
landmark:
  size_mm: 60
"""
    put("fuzz_recording_meta", "sim", meta)
    put("fuzz_recording_meta", "flow", "{format_version: 1, image: {width_px: 1, height_px: 1}, "
        "intrinsics: {fx: 1, fy: 1, cx: 0, cy: 0}, distortion: {k1: 0, k2: 0, p1: 0, p2: 0, "
        "k3: 0}, mount: {height_mm: 1, offset_x_mm: 0, offset_y_mm: 0, yaw_deg: -179.9}, "
        "landmark: {size_mm: 1}}\n")
    put("fuzz_recording_frames", "sim", "t_ns,file\n10000000000,frames/000000.png\n"
        "10066666667,frames/000001.png\n10133333333,sub/dir/x.png\r\n")
    put("fuzz_recording_frames", "escape", "t_ns,file\n1,../x.png\n2,/etc/passwd\n3,a/./b.png\n")
    put("fuzz_recording_odom", "sim", "t_ns,v_mps,omega_radps\n10000000000,0,0\n"
        "10010000000,0.00638906345,0.0156820299\n10020000000,-20,1e-3\n4611686018427387904,20,-20\n")
    put("fuzz_recording_truth", "sim", "t_ns,x_mm,y_mm,theta_deg\n10000000000,-500.0000,20.0000,0.000000\n"
        "10010000000,-499.9750,20.0000,-179.999999\n10020000000,1e9,-1e9,180\n")
    # Configuration: the shipped example, a minimal live one, and the finding-1 inputs.
    with open(os.path.join(ROOT, "firmware", "config", "agvloc.yaml"), "rb") as f:
        put("fuzz_config", "shipped", f.read())
    put("fuzz_config", "minimal", "intrinsics: {fx: 769.23, fy: 769.23, cx: 319.5, cy: 239.5}\n")
    put("fuzz_config", "sections", "intrinsics: {fx: 700, fy: 700, cx: 320, cy: 240}\n"
        "can:\n  extended_ids: true\n  base_id: 0x18FF0000\n  odometry: {mode: wheels, id: 0x123}\n"
        "loop: {realtime_priority: 50, vision_priority: 40, spin_before_deadline_us: 200}\n"
        "vision: {qr_max_missing_modules: 12, robust: false}\n"
        "fusion: {gate_probability: 0.99, max_fix_delay_ms: 250}\nreplay: {fix_delay_ms: 10}\n"
        "landmark: {size_mm: 60, map: ../maps/grid.csv}\n")
    put("fuzz_config", "seqkey", "[a]: 1")
    put("fuzz_config", "mapkey", "camera:\n  {x: 1}: 2")
    put("fuzz_config", "dup", "loop:\n  output_rate_hz: 50\n  output_rate_hz: 200\n")
    # candump -l lines.
    for i, s in enumerate(["(1436509052.249713) can0 123#DEADBEEF",
                           "(1436509052.249713) can0 12345678#0102",
                           "(1.000000) vcan0 123#R2 T", "(1.5) can0 20000004#0004000000000000",
                           "(1.000000) can0 123#1122334455667788_F\r\n",
                           "(9223372036.854775807) can0 7FF#", "(9223372037.0) can0 123#"]):
        put("fuzz_candump", f"seed{i}", s)
    # CAN odometry: config byte, then 12-byte frames (see fuzz_can_odometry.cpp).
    def frames(cfg, items):
        out = bytes([cfg])
        for flags, dt, a, b, counter in items:
            out += bytes([flags, dt & 0xFF]) + struct.pack("<hh", a, b) + bytes([counter]) + bytes(7)
        return out
    seq = [(1, 10, 500, -100, c % 15) for c in range(20)]
    put("fuzz_can_odometry", "twist", frames(0x31, seq))
    put("fuzz_can_odometry", "wheels_gaps", frames(0x30, [(1, 10, 400, 420, c) for c in (0, 1, 3, 7, 7, 8)]))
    put("fuzz_can_odometry", "unprotected", frames(0x02, [(0, 10, 0, 0, 0), (8, 10, 0, 0, 0)]))
    put("fuzz_can_odometry", "stale", frames(0x11, [(1, 10, 1, 1, 0), (1, -20, 1, 1, 1), (3, 5, 1, 1, 2)]))
    # PNG: grey 8/16/1 bit, RGB, RGBA, palette, grey+alpha, interlaced, with text chunk.
    g = [bytes((x * 16 + y) & 0xFF for x in range(16)) for y in range(8)]
    put("fuzz_png", "gray8", png(16, 8, 0, 8, g))
    put("fuzz_png", "gray16", png(4, 2, 0, 16, [bytes(range(8)), bytes(range(8, 16))]))
    put("fuzz_png", "gray1", png(9, 2, 0, 1, [b"\xAA\x80", b"\x55\x00"]))
    put("fuzz_png", "rgb", png(2, 2, 2, 8, [b"\xff\0\0\0\xff\0", b"\0\0\xff\x80\x80\x80"]))
    put("fuzz_png", "rgba", png(1, 1, 6, 8, [b"\x10\x20\x30\x40"]))
    put("fuzz_png", "gray_alpha", png(2, 1, 4, 8, [b"\x10\xff\x20\x00"]))
    plte = struct.pack(">I", 6) + b"PLTE" + b"\0\0\0\xff\xff\xff"
    plte += struct.pack(">I", zlib.crc32(b"PLTE\0\0\0\xff\xff\xff") & 0xFFFFFFFF)
    put("fuzz_png", "palette", png(3, 1, 3, 8, [b"\0\1\0"], extra=plte))
    put("fuzz_png", "interlaced", png(16, 8, 0, 8, g, interlace=1))
    text = b"Software\0agvloc"
    put("fuzz_png", "text", png(16, 8, 0, 8, g, extra=struct.pack(">I", len(text)) + b"tEXt" + text +
                                struct.pack(">I", zlib.crc32(b"tEXt" + text) & 0xFFFFFFFF)))
    # Vision: the unmutated frames, and a few painted rectangles on each.
    for i in range(4):
        put("fuzz_vision", f"base{i}", bytes([i]))
        put("fuzz_vision", f"paint{i}", bytes([i, 0x40, 0x01, 0xF0, 0x00, 0xFF, 0x00,
                                               0x30, 0x81, 0x10, 0x01, 0x77, 0x80]))
    # VDA 5050 instantActions: initPosition for both versions (a leading tab, odd, picks 3.0.0 in
    # the harness), another map, another action, a truncated message.
    def vda(version, action, params):
        import json
        return json.dumps({"headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z",
                           "version": version, "manufacturer": "acme", "serialNumber": "agv-7",
                           "actions": [{"actionId": "a1", "actionType": action,
                                        "blockingType": "NONE", "actionParameters": params}]})
    good = [{"key": "x", "value": 1.5}, {"key": "y", "value": -2}, {"key": "theta", "value": 0.5},
            {"key": "mapId", "value": "hall-1"}, {"key": "lastNodeId", "value": "n1"}]
    put("fuzz_vda_action", "init_v2", vda("2.1.0", "initPosition", good))
    put("fuzz_vda_action", "init_v3", "\t" + vda("3.0.0", "initializePosition", good))
    put("fuzz_vda_action", "other_map",
        vda("2.1.0", "initPosition", good[:3] + [{"key": "mapId", "value": "x"}]))
    put("fuzz_vda_action", "other_action", vda("2.1.0", "startPause", []))
    put("fuzz_vda_action", "truncated", '{"headerId": [[[')
    det = ('{"v":1,"camera":"cam-a","t_ns":1000000000,"seq":7,"tags":[{"id":3,"code":123456,'
           '"hamming":0,"margin":9,"restricted":false,"contrast":140.5,"sigma_px":0.05,'
           '"corners_px":[[10,20],[70,21],[69,80],[9,79]],"level":"full"}]}')
    put("fuzz_detection_msg", "one_tag", det)
    put("fuzz_detection_msg", "empty", det.split('"tags"')[0] + '"tags":[]}')
    put("fuzz_detection_msg", "other_camera", det.replace("cam-a", "cam-z"))
    put("fuzz_detection_msg", "truncated", det[:90])
    # Orders for the overhead tracker's route prior: topic line, payload; messages split by NUL.
    def order(oid, update, first, xs, released=None):
        import json
        n = len(xs)
        rel = released or [True] * n
        nodes = [{"nodeId": "%s_n%d" % (oid, first + i), "sequenceId": 2 * (first + i),
                  "released": rel[i], "actions": [],
                  "nodePosition": {"x": x, "y": 0.5, "mapId": "hall"}} for i, x in enumerate(xs)]
        edges = [{"edgeId": "%s_e%d" % (oid, first + i), "sequenceId": 2 * (first + i) + 1,
                  "released": rel[i + 1], "startNodeId": nodes[i]["nodeId"],
                  "endNodeId": nodes[i + 1]["nodeId"], "actions": []} for i in range(n - 1)]
        return "uagv/v2/acme/agv-2/order\n" + json.dumps({
            "headerId": 1, "timestamp": "2026-01-01T00:00:00.000Z", "version": "2.1.0",
            "manufacturer": "acme", "serialNumber": "agv-2", "orderId": oid,
            "orderUpdateId": update, "nodes": nodes, "edges": edges})
    put("fuzz_order_intake", "one", order("o1", 0, 0, [1.0, 2.0, 3.0]))
    put("fuzz_order_intake", "stitched", order("o1", 0, 0, [1.0, 2.0]) + "\0" +
        order("o1", 1, 1, [2.0, 4.0]) + "\0" + order("o1", 1, 1, [2.0, 4.0]))
    put("fuzz_order_intake", "horizon", order("o1", 0, 0, [1.0, 2.0, 3.0], [True, False, False]))
    put("fuzz_order_intake", "bad_topic", order("o1", 0, 0, [1.0]).replace("/order", "/state"))
    put("fuzz_order_intake", "truncated", order("o1", 0, 0, [1.0, 2.0])[:120])
    # calibrate check --placements CSV (docs/guide/commissioning.md): placements of several
    # frames, recording directories, comments and CRLF, and near misses.
    put("fuzz_placements", "three", "frame,x_mm,y_mm,heading_deg\nc1.png,300,0,0\nc2.png,300,0,0\n"
        "c3.png,250,-60,90.5\n/abs/rec,250,-60,90.5\n")
    put("fuzz_placements", "comments_crlf", "# taped 2026-11-28\r\n\r\nframe,x_mm,y_mm,heading_deg\r\n"
        "rec1,-1e3,+2.5e1,-179.9\r\n")
    put("fuzz_placements", "bad_header", "frame,x,y,heading\nc1.png,1,2,3\n")
    put("fuzz_placements", "bad_row", "frame,x_mm,y_mm,heading_deg\nc1.png,1,2\n,1,2,3\nc,1,2,3x\n")
    put("fuzz_placements", "nonfinite", "frame,x_mm,y_mm,heading_deg\nc1.png,inf,0,0\nc2.png,nan,0,0\n")
    # config apply: a configuration, then snippets after "---snippet---" lines (fuzz_config_apply).
    sep = "\n---snippet---\n"
    base = ("# vehicle 7\ncamera:\n  device: /dev/video0\nintrinsics:\n  fx: 700  # old\n  fy: 700\n"
            "  cx: 319.5\n  cy: 239.5\nmounting:\n  offset_x_mm: 250\n  height_mm: 200\n"
            "odometry: {speed_scale: 1.0}\n")
    intr = "intrinsics:\n  fx: 769.2\n  fy: 769.3\n  cx: 320.1\n  cy: 240.2\n  k1: -0.12\n"
    veh = ("mounting:\n  offset_x_mm: 253.7\n  offset_y_mm: -4.2\n  yaw_deg: 1.29\n  height_mm: 121.5\n"
           "odometry:\n  speed_scale: 1.02\ncamera:\n  time_offset_ms: 12.0\n")
    put("fuzz_config_apply", "both", base + sep + intr + sep + veh)
    put("fuzz_config_apply", "empty_base", sep + veh)
    put("fuzz_config_apply", "flow", "mounting: {offset_x_mm: 1, height_mm: 2}\n" + sep + veh)
    put("fuzz_config_apply", "conflict", base + sep + veh + sep + veh.replace("1.02", "1.03"))
    put("fuzz_config_apply", "unknown_key", base + sep + "mounting:\n  offset_z_mm: 3\n")
    put("fuzz_config_apply", "twice", base + sep + "mounting:\n  height_mm: 1\n  height_mm: 2\n")
    # report's replay CSVs: the first byte picks the file (even poses.csv, odd fixes.csv).
    poses_h = ("t_ns,valid,health,x_mm,y_mm,theta_deg,v_mps,omega_radps,sigma_x_mm,sigma_y_mm,"
               "sigma_theta_deg,time_since_fix_ms,faults,rejections\n")
    put("fuzz_report_csv", "poses", b"\x00" + (poses_h +
        "1000000000,0,2,0.0000,0.0000,0.00000,0.00000,0.000000,1000.0000,1000.0000,57.29578,-1.0,0,0\n"
        "1010000000,1,0,1000.5000,-2000.2500,90.00000,0.50000,0.010000,0.5000,0.6000,0.01000,12.5,4,1\n"
        ).encode())
    put("fuzz_report_csv", "fixes", b"\x01" + (
        "t_ns,status,landmark_id,e_x_mm,e_y_mm,e_phi_deg,x_mm,y_mm,theta_deg,sigma_x_mm,sigma_y_mm,"
        "sigma_theta_deg,vision_ms,search,identity\n"
        "1000000000,ok,7,1.0000,-2.0000,0.50000,1000.0000,2000.0000,-90.00000,0.0100,0.0100,0.00100,"
        "0.310,full,payload\n1100000000,no landmark,0,0,0,0,0,0,0,0,0,0,0.200,full,none\n").encode())
    put("fuzz_report_csv", "poses_bad", b"\x02" + b"t_ns,valid,health,x_mm,y_mm,theta_deg\n"
        b"1,1,0,nan,0,0,0,0,0,0,0,1e300,0,0\n")


if __name__ == "__main__":
    main()
