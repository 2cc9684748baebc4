#!/usr/bin/env python3
"""Every file and name that ARCHITECTURE.md cites (in `backticks`) exists in the repository.

A cited path (it has a '/' or a source extension; `<stage>`-style placeholders and a trailing `.*`
match anything) must name a tracked file or folder, resolved from the root or as the tail of a tracked
path (the engine section cites paths under kernels/). `path: name` must find `name` in that file.
Every other identifier of a citation (Engine<Real>::detect gives Engine, Real, detect) must occur as
a whole word in a tracked source file (C++, CUDA, CMake, shell). Prints each missing citation and
exits 1 if there is any.
"""
import fnmatch
import re
import subprocess
import sys

DOC = "ARCHITECTURE.md"
SOURCE_SUFFIXES = (".cpp", ".hpp", ".cu", ".cuh", ".h", ".txt", ".sh", ".py", ".gp", ".cmake")
PATH_SUFFIXES = SOURCE_SUFFIXES + (".md",)


def tracked_files():
    out = subprocess.run(["git", "ls-files"], check=True, capture_output=True, text=True).stdout
    return [f for f in out.splitlines() if f]


def main():
    files = tracked_files()
    folders = {f.rsplit("/", k)[0] + "/" for f in files for k in range(1, f.count("/") + 1)}
    sources = [f for f in files if f.endswith(SOURCE_SUFFIXES) and not f.startswith("tests/data/")]
    words = set()
    text_of = {}
    for f in sources:
        with open(f, encoding="utf-8", errors="replace") as h:
            text_of[f] = h.read()
        words.update(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text_of[f]))

    with open(DOC, encoding="utf-8") as h:
        doc = h.read()
    doc = re.sub(r"```.*?```", "", doc, flags=re.S)  # fenced blocks are drawings, not citations
    spans = [s.replace("\n", " ") for s in re.findall(r"`([^`]+)`", doc)]

    def resolve(path):
        """The tracked files a cited path names (empty: none)."""
        pattern = re.sub(r"<[^>]*>", "*", path)
        if pattern.endswith("/"):
            hits = [d for d in folders if d == pattern or d.endswith("/" + pattern)]
            return hits
        candidates = [pattern]
        if not pattern.endswith(PATH_SUFFIXES) and not pattern.endswith("*"):
            candidates.append(pattern + ".*")  # a stem: src/io/scene_file → its .hpp / .cpp
        hits = []
        for c in candidates:
            hits += [f for f in files if fnmatch.fnmatch(f, c) or fnmatch.fnmatch(f, "*/" + c)]
        return hits

    def is_path(token):
        return "/" in token or token.endswith(PATH_SUFFIXES) or token.endswith(".*")

    missing = []
    for span in spans:
        if span.startswith("../"):  # outside the repository
            continue
        m = re.fullmatch(r"\s*([^\s:]+):\s+([A-Za-z_][A-Za-z0-9_]*)\s*", span)
        if m and is_path(m.group(1)):
            hits = resolve(m.group(1))
            if not hits:
                missing.append(f"`{span}`: no file {m.group(1)}")
            elif not any(re.search(r"\b" + m.group(2) + r"\b", text_of.get(f, "")) for f in hits):
                missing.append(f"`{span}`: {m.group(2)} is not in {', '.join(hits)}")
            continue
        for token in re.split(r"[\s,()]+", span):
            token = token.strip("\"'<>")  # #include "io/scene_file.hpp", <mpi.h>
            if not re.search(r"[A-Za-z0-9_]", token) or token.startswith((".", "-")):
                continue  # a separator, an extension (`.cu`) or a command-line option
            if is_path(token):
                if not resolve(token):
                    missing.append(f"`{span}`: no file {token}")
                continue
            for name in re.findall(r"[A-Za-z_][A-Za-z0-9_]*\*?", token):
                if name.endswith("*"):
                    if not any(w.startswith(name[:-1]) for w in words):
                        missing.append(f"`{span}`: no name {name}")
                elif name not in words:
                    missing.append(f"`{span}`: no name {name}")
    for line in missing:
        print(f"{DOC}: {line}")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
