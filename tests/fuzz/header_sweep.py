#!/usr/bin/env python3
"""Structure-aware sweep of the two damage kinds libFuzzer found last (issue #21, BENCHMARKS §7).

  tests/fuzz/header_sweep.py [contactgrid=build/src/contactgrid] [work dir=/tmp/cg_header_sweep]

From a generated scene, a polydisperse scene and their contact files (basic fp64, full fp32):
- shared flags: every message of every v1 object header (root, groups, datasets) flagged "shared",
  its body left as is, or made a shared-message table id (versions 2 and 3) or a reference to its
  own header;
- local heaps: every group's free list made to loop (at each offset, and through two blocks), to
  start or end outside the heap, a block of size 0 or past the end, and the heap's size changed.
Each mutant goes through detect and validate (scenes) or compare and validate (contact files), 10 s
deadline each; the exit must be 0, 1 or 3. Prints a tally; exit 1 on a crash or a hang.
"""
import os
import subprocess
import sys
from collections import Counter


def u(b, o, n):
    return int.from_bytes(b[o:o + n], "little")


def p8(b, o, v):
    b[o:o + 8] = (v & (2**64 - 1)).to_bytes(8, "little")


def headers(b):
    """(address, [(message offset, type)]) of every v1 object header reachable from the root."""
    seen, out = set(), []

    def walk_stab(btree, heap):
        if b[btree:btree + 4] != b"TREE":
            return
        level, n = b[btree + 5], u(b, btree + 6, 2)
        for k in range(n):
            child = u(b, btree + 24 + 8 + 16 * k, 8)
            if level > 0:
                walk_stab(child, heap)
            elif b[child:child + 4] == b"SNOD":
                for e in range(u(b, child + 6, 2)):
                    walk_header(u(b, child + 8 + 40 * e + 8, 8))

    def walk_header(a):
        if a in seen or a + 16 > len(b):
            return
        seen.add(a)
        messages, chunks, i = [], [(a + 16, u(b, a + 8, 4))], 0
        while i < len(chunks) and i < 16:
            at, size = chunks[i]
            i += 1
            p = at
            while p + 8 <= min(at + size, len(b)):
                t, s = u(b, p, 2), u(b, p + 2, 2)
                messages.append((p, t))
                if t == 0x10:
                    chunks.append((u(b, p + 8, 8), u(b, p + 16, 8)))
                if t == 0x11:
                    walk_stab(u(b, p + 8, 8), u(b, p + 16, 8))
                p += 8 + s
        out.append((a, messages))

    walk_header(u(b, 64, 8))  # superblock v0: the root's symbol table entry, its header address
    return out


def shared_mutants(b):
    for a, messages in headers(b):
        for p, t in messages:
            if t == 0:
                continue
            for variant in range(4):
                m = bytearray(b)
                m[p + 4] |= 0x02
                if variant == 1:
                    m[p + 8], m[p + 9] = 2, 1
                elif variant == 2:
                    m[p + 8], m[p + 9] = 3, 1
                elif variant == 3:
                    m[p + 8], m[p + 9] = 3, 2
                    p8(m, p + 10, a)
                yield f"shared_{a}_{p}_{t}_{variant}", m


def heap_mutants(b):
    i = b.find(b"HEAP")
    while i >= 0:
        size, data = u(b, i + 8, 8), u(b, i + 24, 8)
        for x in range(0, max(size - 15, 1), 8):
            m = bytearray(b)
            p8(m, i + 16, x)
            p8(m, data + x, x)
            p8(m, data + x + 8, 16)
            yield f"heap{i}_self{x}", m
        if size >= 48:
            m = bytearray(b)
            p8(m, i + 16, 8)
            for o, v in ((8, 24), (16, 16), (24, 8), (32, 16)):
                p8(m, data + o, v)
            yield f"heap{i}_two", m
        for name, v in (("size_m8", size - 8), ("size", size), ("0", 0), ("big", 2**63)):
            m = bytearray(b)
            p8(m, i + 16, v)
            yield f"heap{i}_head_{name}", m
        for name, nxt, sz in (("zero", 1, 0), ("past_end", 1, size), ("next_past", size, 16), ("huge", 1, 2**62)):
            m = bytearray(b)
            p8(m, i + 16, 8)
            p8(m, data + 8, nxt)
            p8(m, data + 16, sz)
            yield f"heap{i}_block_{name}", m
        for name, v in (("0", 0), ("big", 2**40), ("p8", size + 8)):
            m = bytearray(b)
            p8(m, i + 8, v)
            yield f"heap{i}_dsize_{name}", m
        i = b.find(b"HEAP", i + 1)


def main():
    cg = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else "build/src/contactgrid")
    work = sys.argv[2] if len(sys.argv) > 2 else "/tmp/cg_header_sweep"
    os.makedirs(work, exist_ok=True)
    f = lambda name: os.path.join(work, name)  # noqa: E731
    run = lambda *a: subprocess.run([cg, *a], check=True, capture_output=True)  # noqa: E731
    run("generate", f("spheres.h5"), "-n", "20", "--seed", "1", "-q")
    run("generate", f("poly.h5"), "-n", "30", "--kind", "polydisperse", "--seed", "2", "-q")
    run("detect", f("spheres.h5"), "-o", f("contacts.h5"), "--backend", "cpu", "-q")
    run("detect", f("poly.h5"), "-o", f("full.h5"), "--backend", "cpu", "--fields", "full", "--precision",
        "fp32", "-q")
    tally, bad = Counter(), []
    for source, scene in (("spheres.h5", True), ("poly.h5", True), ("contacts.h5", False), ("full.h5", False)):
        b = bytearray(open(f(source), "rb").read())
        for name, m in [*shared_mutants(b), *heap_mutants(b)]:
            mutant = f("mutant.h5")
            open(mutant, "wb").write(m)
            commands = ([["detect", mutant, "-o", f("out.h5"), "--backend", "cpu", "-q"],
                         ["validate", mutant, f("contacts.h5")]] if scene else
                        [["compare", mutant, f("contacts.h5")], ["validate", f("spheres.h5"), mutant]])
            for c in commands:
                try:
                    rc = subprocess.run([cg, *c], capture_output=True, timeout=10).returncode
                except subprocess.TimeoutExpired:
                    rc = "hang"
                tally[(c[0], rc)] += 1
                if rc not in (0, 1, 3):
                    bad.append(f"{source} {name}: {c[0]} -> {rc}")
                    os.replace(mutant, f(f"finding_{source}_{name}.h5"))
                    break
    for (command, rc), n in sorted(tally.items(), key=str):
        print(f"{command:9} exit {rc}: {n}")
    for line in bad:
        print("FINDING", line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
