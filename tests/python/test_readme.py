"""The README's C++ and Python examples of "From another project": the C++ one is the region of
tests/consumer/two_spheres.cpp that the consumer_package test builds and runs; the Python one runs here."""
import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def block(marker, language):
    with open(os.path.join(ROOT, "README.md")) as f:
        text = f.read()
    m = re.search(rf"<!-- example: {marker} -->\n```{language}\n(.*?)```\n", text, re.S)
    assert m, f"README.md has no {language} block after <!-- example: {marker} -->"
    return m.group(1)


def test_the_cpp_example_is_the_consumers_code():
    with open(os.path.join(ROOT, "tests", "consumer", "two_spheres.cpp")) as f:
        source = f.read()
    region = re.search(r"// EXAMPLE-BEGIN\n(.*?)// EXAMPLE-END\n", source, re.S).group(1)
    assert block("consumer", "cpp") == region


def test_the_python_example_runs():
    exec(compile(block("python", "python"), "README.md", "exec"), {})
