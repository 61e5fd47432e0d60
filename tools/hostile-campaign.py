#!/usr/bin/env python3
"""Reruns issue 57's fault campaign against a cdvol binary.

    tools/hostile-campaign.py CDVOL WORKDIR [> table.md]

Each case writes one hostile input under WORKDIR (sparse where it is
huge: nothing large reaches the disk), runs `cdvol` on it under a 4 GiB
address-space limit (`ulimit -v`) and `/usr/bin/time -v`, killed after
60 s, and prints a Markdown row: what was tried, the exit status (a
signal is `SIGxxx`), seconds, peak RSS, whether an output file appeared,
and the first line of the message. The serve cases send raw HTTP to
`cdvol serve` and check that it still answers /api/status afterwards.
docs/RELIABILITY.md ("Hostile inputs and clients") holds a run's table.
"""

import gzip
import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
import zlib

LIMIT_KIB = 4 << 20


def run(cdvol, args, cwd, stdin=None, limit=True):
    """(status, seconds, peak RSS MiB, stderr) of `cdvol ARGS` under the
    limits (without the address-space limit when `limit` is false)."""
    cmd = (
        (f"ulimit -v {LIMIT_KIB}; " if limit else "")
        + f"exec /usr/bin/time -v -o time.txt timeout -s KILL 60 {cdvol} {args}"
    )
    t = time.monotonic()
    p = subprocess.run(
        ["bash", "-c", cmd], cwd=cwd, capture_output=True, text=True, input=stdin
    )
    took = time.monotonic() - t
    rss = 0.0
    try:
        for line in open(os.path.join(cwd, "time.txt")):
            if "Maximum resident set size" in line:
                rss = int(line.split(":")[1]) / 1024
            m = re.search(r"Command terminated by signal (\d+)", line)
            if m:
                p.returncode = -int(m.group(1))
    except OSError:
        pass
    if p.returncode == 137 or p.returncode == -9:
        status = "SIGKILL (60 s)"
    elif p.returncode < 0:
        status = signal.Signals(-p.returncode).name
    else:
        status = str(p.returncode)
    return status, took, rss, p.stderr


def first_line(err):
    lines = [l for l in err.splitlines() if l.strip() and "Command" not in l]
    errors = [l for l in lines if "error:" in l]
    s = (errors or lines or [""])[0]
    s = s.replace("|", "\\|")
    return s if len(s) <= 160 else s[:157] + "..."


ROWS = []


def row(what, result, outputs=()):
    status, took, rss, err = result
    made = [o for o in outputs if os.path.exists(o)]
    ROWS.append(
        f"| {what} | {status} | {took:.2f} | {rss:.0f} | "
        f"{'yes: ' + ', '.join(map(os.path.basename, made)) if made else 'no'} | "
        f"{first_line(err)} |"
    )


# ---- inputs ----


def write(path, data):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def sparse(path, head, size):
    write(path, head)
    os.truncate(path, size)


def nrrd(path, fields, payload=b""):
    text = "NRRD0004\n" + "".join(f"{k}: {v}\n" for k, v in fields.items()) + "\n"
    write(path, text.encode() + payload)


def base_nrrd_fields(**kw):
    f = {
        "type": "uint8",
        "dimension": "3",
        "sizes": "4 4 4",
        "encoding": "raw",
        "spacings": "1 1 1",
    }
    f.update(kw)
    return f


def nifti(pixdim=1.0, gz=False, flip_crc=False):
    h = bytearray(352)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, 3, 4, 4, 4, 1, 1, 1, 1)
    struct.pack_into("<hh", h, 70, 2, 8)  # uint8
    struct.pack_into("<8f", h, 76, 1.0, pixdim, pixdim, pixdim, 1, 1, 1, 1)
    struct.pack_into("<f", h, 108, 352.0)
    struct.pack_into("<f", h, 112, 1.0)
    h[344:348] = b"n+1\0"
    data = bytes(h) + bytes(range(64))
    if not gz:
        return data
    z = bytearray(gzip.compress(data))
    if flip_crc:
        z[-8] ^= 1
    return bytes(z)


def el(group, elem, vr, value):
    """An explicit VR little endian DICOM element."""
    tag = struct.pack("<HH", group, elem)
    if len(value) % 2:
        value += b"\0" if vr in ("UI", "OB") else b" "
    if vr in ("OB", "OW", "SQ", "UN", "UT"):
        return tag + vr.encode() + b"\0\0" + struct.pack("<I", len(value)) + value
    return tag + vr.encode() + struct.pack("<H", len(value)) + value


def dicom(k, rows=8, cols=8, spacing="0.5\\0.5", slope="1", ts="1.2.840.10008.1.2.1",
          pixel=None, extra=b""):
    ts_b = ts.encode()
    meta_body = (
        el(2, 1, "OB", b"\0\1")
        + el(2, 2, "UI", b"1.2.840.10008.5.1.4.1.1.2")
        + el(2, 3, "UI", f"1.2.3.4.{k}".encode())
        + el(2, 0x10, "UI", ts_b)
    )
    meta = el(2, 0, "UL", struct.pack("<I", len(meta_body))) + meta_body
    ds = (
        el(8, 0x16, "UI", b"1.2.840.10008.5.1.4.1.1.2")
        + el(8, 0x18, "UI", f"1.2.3.4.{k}".encode())
        + el(8, 0x60, "CS", b"CT")
        + el(0x20, 0x0E, "UI", b"1.2.3.4")
        + el(0x20, 0x32, "DS", f"0\\0\\{k}".encode())
        + el(0x20, 0x37, "DS", b"1\\0\\0\\0\\1\\0")
        + extra
        + el(0x28, 2, "US", struct.pack("<H", 1))
        + el(0x28, 4, "CS", b"MONOCHROME2")
        + el(0x28, 0x10, "US", struct.pack("<H", rows))
        + el(0x28, 0x11, "US", struct.pack("<H", cols))
        + el(0x28, 0x30, "DS", spacing.encode())
        + el(0x28, 0x100, "US", struct.pack("<H", 16))
        + el(0x28, 0x101, "US", struct.pack("<H", 16))
        + el(0x28, 0x102, "US", struct.pack("<H", 15))
        + el(0x28, 0x103, "US", struct.pack("<H", 0))
        + el(0x28, 0x1052, "DS", b"0")
        + el(0x28, 0x1053, "DS", slope.encode())
    )
    if pixel is None:
        pixel = el(0x7FE0, 0x10, "OW", bytes(2 * rows * cols))
    return b"\0" * 128 + b"DICM" + meta + ds + pixel


def rle_pixel():
    frag = bytearray(64)
    struct.pack_into("<III", frag, 0, 2, 64, 70)
    frag += bytes([5, 1, 2, 3, 4, 5, 0x81, 9, 0x7F, 0x33])
    return (
        struct.pack("<HH", 0x7FE0, 0x10) + b"OB\0\0" + b"\xff\xff\xff\xff"
        + struct.pack("<HHI", 0xFFFE, 0xE000, 0)
        + struct.pack("<HHI", 0xFFFE, 0xE000, len(frag)) + bytes(frag)
        + struct.pack("<HHI", 0xFFFE, 0xE0DD, 0)
    )


def nested(depth):
    seq = struct.pack("<HH", 0x29, 0x1010) + b"SQ\0\0" + b"\xff\xff\xff\xff"
    item = struct.pack("<HHI", 0xFFFE, 0xE000, 0xFFFFFFFF)
    end = struct.pack("<HHI", 0xFFFE, 0xE00D, 0) + struct.pack("<HHI", 0xFFFE, 0xE0DD, 0)
    return (seq + item) * depth + end * depth


def series(d, n=3, **kw):
    for k in range(n):
        write(os.path.join(d, f"s{k}.dcm"), dicom(k, **kw))


# ---- serve ----


def http(port, raw, timeout=10):
    try:
        s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    except OSError as e:
        return f"no connection ({e.strerror})"
    try:
        s.sendall(raw)
        got = b""
        while True:
            b = s.recv(65536)
            if not b:
                break
            got += b
    except OSError:
        pass
    finally:
        s.close()
    return got.split(b"\r\n", 1)[0].decode(errors="replace")


def serve_cases(cdvol, work, packed):
    p = subprocess.Popen(
        ["bash", "-c", f"ulimit -v {LIMIT_KIB}; exec {cdvol} serve {packed} --bind 127.0.0.1:0"],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
    )
    line = p.stderr.readline()
    port = int(re.search(r":(\d+)/", line).group(1))
    status_rq = b"GET /api/status HTTP/1.0\r\nHost: localhost\r\n\r\n"
    cases = [
        ("serve: GET with Content-Length: 99999999999",
         b"GET /api/status HTTP/1.1\r\nHost: localhost\r\nContent-Length: 99999999999\r\n\r\nabc"),
        ("serve: chunked body of 2^48 bytes",
         b"GET /api/status HTTP/1.1\r\nHost: localhost\r\nTransfer-Encoding: chunked\r\n\r\nffffffffffff\r\n"),
        ("serve: a 1 MiB header", b"GET / HTTP/1.1\r\nX: " + b"a" * (1 << 20) + b"\r\n\r\n"),
        ("serve: 10,000 header lines", b"GET / HTTP/1.1\r\n" + b"X: 1\r\n" * 10000 + b"\r\n"),
    ]
    for what, raw in cases:
        t = time.monotonic()
        first = http(port, raw)
        took = time.monotonic() - t
        alive = p.poll() is None and "200" in http(port, status_rq)
        ROWS.append(
            f"| {what} | {'answers' if alive else 'DIED'} | {took:.2f} | - | no | {first} |"
        )
    # Status behind a flood of renders: 12 clients at once, no sessions
    # (none cancels another), so they queue for the render slot.
    import threading
    answers = []

    def render(i):
        answers.append(http(port, (
            f"GET /api/image?mode=surface&shadows=1&w=1024&h=1024&az={i} "
            "HTTP/1.0\r\nHost: localhost\r\n\r\n").encode(), 120))

    flood = [threading.Thread(target=render, args=(i,)) for i in range(12)]
    for th in flood:
        th.start()
    time.sleep(0.3)
    t = time.monotonic()
    first = http(port, status_rq)
    took = time.monotonic() - t
    for th in flood:
        th.join()
    drawn = sum("200" in a for a in answers)
    ROWS.append(
        f"| serve: /api/status behind 12 queued shadowed 1024^2 renders "
        f"({drawn} of 12 drawn) | {'answers' if p.poll() is None else 'DIED'} | "
        f"{took:.2f} | - | no | {first} |"
    )
    rss = 0
    try:
        for line in open(f"/proc/{p.pid}/status"):
            if line.startswith("VmHWM:"):
                rss = int(line.split()[1]) / 1024
    except OSError:
        pass
    ROWS.append(f"| serve: peak RSS after all the above | {'answers' if p.poll() is None else 'DIED'} | - | {rss:.0f} | no | |")
    p.kill()
    p.wait()


def main():
    cdvol, work = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    os.makedirs(work, exist_ok=True)
    os.chdir(work)

    def case(name, what, args, outputs=(), stdin=None, limit=True):
        d = os.path.join(work, name)
        row(what, run(cdvol, args, d, stdin, limit), [os.path.join(d, o) for o in outputs])

    # DICOM
    series("dcm-rle/in", ts="1.2.840.10008.1.2.5", pixel=rle_pixel())
    case("dcm-rle", "DICOM: RLE Lossless with garbage data", "prep -q in -o out.cdv --iso 100", ["out.cdv"])
    series("dcm-nest/in", extra=nested(100_000))
    case("dcm-nest", "DICOM: 100,000 nested sequences", "prep -q in -o out.cdv --iso 100", ["out.cdv"])
    series("dcm-huge/in", rows=65535, cols=65535, pixel=el(0x7FE0, 0x10, "OW", bytes(128)))
    case("dcm-huge", "DICOM: Rows = Columns = 65535", "prep -q in -o out.cdv --iso 100", ["out.cdv"])
    series("dcm-space/in", spacing="1e-300\\1e-300")
    case("dcm-space", "DICOM: PixelSpacing 1e-300", "prep -q in -o out.cdv --iso 100", ["out.cdv"])
    series("dcm-slope/in", slope="NaN")
    case("dcm-slope", "DICOM: RescaleSlope NaN", "prep -q in -o out.cdv --iso 100", ["out.cdv"])
    series("dcm-nopos/in", n=4)
    b = dicom(2)
    b = b.replace(el(0x20, 0x32, "DS", b"0\\0\\2"), b"")
    write("dcm-nopos/in/s2.dcm", b)
    case("dcm-nopos", "DICOM: one slice without ImagePositionPatient", "prep -q in -o out.cdv --iso 100", ["out.cdv"])
    series("batch/in/good")
    for k in range(3):
        write(f"batch/in/rle/s{k}.dcm", dicom(k, ts="1.2.840.10008.1.2.5", pixel=rle_pixel()).replace(b"1.2.3.4\0", b"1.2.3.5\0"))
        write(f"batch/in/nest/s{k}.dcm", dicom(k, extra=nested(100_000) if k == 0 else b"").replace(b"1.2.3.4\0", b"1.2.3.6\0"))
    case("batch", "prep-batch: a good series beside RLE garbage and deep nesting",
         "prep-batch -q in -o out --iso=-1 --brick 8", ["out/good.cdv", "out/batch.json", "out/rle.cdv", "out/nest.cdv"])

    # NRRD
    for what, size in [("2147483648", "2147483648 2 2"), ("2^36", "68719476736 2 2"),
                       ("2^64-1", "18446744073709551615 2 2")]:
        nrrd(f"nrrd-{what}/x.nrrd", base_nrrd_fields(sizes=size), bytes(64))
        case(f"nrrd-{what}", f"NRRD: sizes {what} 2 2", "prep -q x.nrrd -o out.cdv --iso 100", ["out.cdv"])
    nrrd("nrrd-skip/x.nrrd", base_nrrd_fields(**{"byte skip": "18446744073709551615"}), bytes(range(64)))
    case("nrrd-skip", "NRRD: byte skip 2^64-1", "prep -q x.nrrd -o out.cdv --iso 10", ["out.cdv"])
    z = bytearray(gzip.compress(bytes(range(64))))
    z[-8] ^= 1
    nrrd("nrrd-crc/x.nrrd", base_nrrd_fields(encoding="gzip"), bytes(z))
    case("nrrd-crc", "NRRD gzip: CRC-32 one bit off", "prep -q x.nrrd -o out.cdv --iso 10", ["out.cdv"])
    nrrd("nrrd-space/x.nrrd", base_nrrd_fields(spacings="1e-300 1 1"), bytes(range(64)))
    case("nrrd-space", "NRRD: spacings 1e-300", "prep -q x.nrrd -o out.cdv --iso 10", ["out.cdv"])
    sparse("nrrd-line/x.nrrd", b"NRRD0004\ntype: uint8\n# ", 2_600_000_000)
    case("nrrd-line", "NRRD: a 2.6 GB header of one line", "prep -q x.nrrd -o out.cdv --iso 10", ["out.cdv"])
    nrrd("nrrd-long/x.nrrd", base_nrrd_fields(), bytes(range(64)) + bytes(10))
    case("nrrd-long", "NRRD: raw data 10 bytes longer than its sizes", "prep -q x.nrrd -o out.cdv --iso 10", ["out.cdv"])

    # NIfTI
    write("nii-crc/x.nii.gz", nifti(gz=True, flip_crc=True))
    case("nii-crc", "NIfTI .nii.gz: CRC-32 one bit off", "prep -q x.nii.gz -o out.cdv --iso 10", ["out.cdv"])
    write("nii-space/x.nii", nifti(pixdim=1e-45))
    case("nii-space", "NIfTI: pixdim 1e-45", "prep -q x.nii -o out.cdv --iso 10", ["out.cdv"])

    # Sidecars and options
    sparse("side-huge/x.json", b'{"data": "x.raw", "note": "', 2_600_000_000)
    case("side-huge", "sidecar: 2.6 GB", "prep -q x.json -o out.cdv --iso 10", ["out.cdv"])
    write("memlimit/x.raw", b"")
    os.truncate("memlimit/x.raw", 100000 * 100000 * 2)
    write("memlimit/x.json", json.dumps({"data": "x.raw", "dims": [100000, 100000, 2], "dtype": "u8", "x": 1, "y": 1, "z": 1}).encode())
    # Without the address-space limit: the mapping of the data must
    # succeed for the limit's own check to be reached.
    case("memlimit", "prep --mem-limit 100000000 (MiB) of a 20 GB volume (no ulimit)",
         "prep -q x.json -o out.cdv --iso 10 --mem-limit 100000000", ["out.cdv"], limit=False)

    # Outputs over inputs
    d = os.path.join(work, "writers")
    os.makedirs(d, exist_ok=True)
    subprocess.run([cdvol, "phantom", "ct", "-o", "h.json", "--dims", "48,44,32"], cwd=d, check=True, capture_output=True)
    subprocess.run([cdvol, "prep", "-q", "h.json", "-o", "h.cdv", "--iso", "100"], cwd=d, check=True, capture_output=True)
    subprocess.run(["cp", "h.cdv", "x.png"], cwd=d, check=True)
    before = open(os.path.join(d, "x.png"), "rb").read()
    r = run(cdvol, "histogram x.png -o x.png", d)
    same = open(os.path.join(d, "x.png"), "rb").read() == before
    ROWS.append(f"| histogram x.png -o x.png (x.png a packed file) | {r[0]} | {r[1]:.2f} | {r[2]:.0f} | {'no (input unchanged)' if same else 'INPUT REPLACED'} | {first_line(r[3])} |")
    scan = open(os.path.join(d, "h.json"), "rb").read()
    r = run(cdvol, "export h.cdv --what values -o h.json", d)
    same = open(os.path.join(d, "h.json"), "rb").read() == scan
    ROWS.append(f"| export h.cdv -o h.json (the scan it came from) | {r[0]} | {r[1]:.2f} | {r[2]:.0f} | {'no (scan unchanged)' if same else 'SCAN REPLACED'} | {first_line(r[3])} |")
    tf = json.dumps({"points": [
        {"value": 100, "opacity": 0, "color": [0, 0, 0]},
        {"value": 400, "opacity": 0.5, "color": [1, 1, 1]},
    ]})
    with open(os.path.join(d, "tf.json"), "w") as f:
        f.write(tf)
    r = run(cdvol, "render h.cdv -o tf.png --mode composite --width 64 --height 64 --tf <(cat tf.json)", d)
    row("render --tf <(cat tf.json)", r, [os.path.join(d, "tf.png")])

    # serve
    serve_cases(cdvol, work, os.path.join(d, "h.cdv"))

    print("| case | exit | s | peak RSS MiB | output written | message |")
    print("|---|---|---|---|---|---|")
    for r in ROWS:
        print(r)


if __name__ == "__main__":
    main()
