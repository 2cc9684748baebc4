#!/usr/bin/env python3
"""No history in the code comments of src/, kernels/, comm/ and decomposition/: no commit hash and no
UTC time. Those belong in the git log and BENCHMARKS.md, where a comment may point (house style 32).

A commit hash is a word of 7 to 40 hexadecimal digits with at least one letter and one digit, not a
0x literal; a UTC time is "UTC" or "GMT", an ISO date (2026-11-25) or a clock time with a two-digit
hour (01:36). Prints each finding as file:line and exits 1 if there is any.
"""
import re
import subprocess
import sys

FOLDERS = ["src", "kernels", "comm", "decomposition"]
SUFFIXES = (".cpp", ".hpp", ".cu", ".cuh", ".h")
HASH = re.compile(r"(?<![0-9A-Za-z_.])(?!0x)(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![0-9A-Za-z_])")
TIME = re.compile(r"\b(UTC|GMT)\b|\b20\d\d-[01]\d-[0-3]\d\b|\b[0-2]\d:[0-5]\d\b")


def comments(text):
    """(line number, comment text) of every // and /* */ comment, string and char literals skipped."""
    out = []
    i, line, n = 0, 1, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append((line, text[i + 2:j]))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j
            for k, part in enumerate(text[i + 2:j].split("\n")):
                out.append((line + k, part))
            line += text.count("\n", i, j)
            i = j + 2
        elif c in "\"'":
            if c == '"' and text[max(0, i - 1)] == "R":  # raw string R"d(...)d"
                d = text[i + 1:text.find("(", i)]
                j = text.find(")" + d + '"', i)
                j = n if j < 0 else j + len(d) + 2
            else:
                j = i + 1
                while j < n and text[j] != c and text[j] != "\n":
                    j += 2 if text[j] == "\\" else 1
                j += 1
            line += text.count("\n", i, j)
            i = j
        else:
            i += 1
    return out


def main():
    out = subprocess.run(["git", "ls-files", "--"] + FOLDERS, check=True, capture_output=True, text=True).stdout
    findings = []
    for path in out.splitlines():
        if not path.endswith(SUFFIXES):
            continue
        with open(path, encoding="utf-8", errors="replace") as h:
            text = h.read()
        for line, comment in comments(text):
            for pattern, what in ((HASH, "commit hash"), (TIME, "UTC time")):
                m = pattern.search(comment)
                if m:
                    findings.append(f"{path}:{line}: {what} '{m.group(0)}' in a comment: {comment.strip()}")
    for f in findings:
        print(f)
    if findings:
        print("history (commit hashes, clock times) belongs in the git log and BENCHMARKS.md", file=sys.stderr)
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main())
