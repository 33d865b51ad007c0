#!/usr/bin/env python3
"""Checks that every relative link and every repository path the documentation names exists.

  check_doc_links.py ROOT        check the repository at ROOT; prints each broken reference, exits 1 if any
  check_doc_links.py --self-test  build fixture trees with known good and broken references and check that exactly
                                  the broken ones are reported (so the checker itself cannot rot into a no-op)

What is checked, in every Markdown file of the repository (README.md, docs/*.md, ...), outside fenced code blocks:
- links and images `[text](target)`, `![alt](target)` and `[ref]: target` that are not URLs: the file or folder must
  exist inside the repository, relative to the Markdown file; a `#anchor` must be a heading of the target file;
- inline code that names a repository path (`config/hpds.yaml`, `hpds_core/{src,pcl}/`, `bench/*.cpp`): a token
  whose first component is a top-level entry of the repository (or a known top-level folder) must exist; braces are
  expanded and globs must match something; tokens with placeholders (`<concern>`, `...`, `$VAR`) are skipped;
- inline code that names a public header (`hpds/pipeline/Pipeline.hpp`, `<hpds/hpds.hpp>`): it must exist under an
  include folder of the repository.
In code and build files (C++, CMake, Makefile, scripts, launch, YAML): every `.md` path they name under a top-level
folder of the repository (`docs/ros.md`, `bench/README_QUALITY.md`) must exist.
"""
import os
import re
import sys
import tempfile

# Top-level folders the docs may name even when they do not exist (so a reference to a removed or not yet created
# folder is caught rather than mistaken for prose).
KNOWN_TOP_LEVEL = {"hpds_core", "hpds_node", "config", "launch", "test", "bench", "fuzz", "scripts", "docs", "cmake",
                   "examples", "python", ".ci"}
INCLUDE_DIRS = ["hpds_core/include", "hpds_node/include"]
SOURCE_SUFFIXES = (".cpp", ".hpp", ".h", ".c", ".py", ".sh", ".cmake", ".in", ".launch", ".test", ".yaml", ".yml",
                   ".xml", ".txt")
SOURCE_NAMES = {"Makefile", "CMakeLists.txt", "run"}

FENCE = re.compile(r"^\s*(```|~~~)")
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_DEF = re.compile(r"^\s*\[[^\]]+\]:\s*(\S+)")
INLINE_CODE = re.compile(r"(`+)(.+?)\1")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
MD_IN_SOURCE = re.compile(r"[A-Za-z0-9_./-]*[A-Za-z0-9_-]\.md\b")
URL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def is_skipped_dir(name):
    return name.startswith(".git") or name.startswith("build") or name in {"__pycache__", "node_modules"}


def repo_files(root):
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not is_skipped_dir(d))
        for f in sorted(filenames):
            yield os.path.relpath(os.path.join(dirpath, f), root)


def slugify(heading):
    """GitHub's anchor for a heading: link text kept, lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = re.sub(r"[^\w\- ]", "", text.lower())
    return text.replace(" ", "-")


def anchors_of(path):
    anchors, seen = set(), {}
    in_fence = False
    with open(path, encoding="utf-8") as f:
        for line in f:
            if FENCE.match(line):
                in_fence = not in_fence
                continue
            m = None if in_fence else HEADING.match(line)
            if m:
                slug = slugify(m.group(2))
                n = seen.get(slug, 0)
                anchors.add(slug if n == 0 else "%s-%d" % (slug, n))
                seen[slug] = n + 1
    return anchors


def expand_braces(token):
    m = re.search(r"\{([^{}]*)\}", token)
    if not m:
        return [token]
    out = []
    for alt in m.group(1).split(","):
        out.extend(expand_braces(token[:m.start()] + alt + token[m.end():]))
    return out


def inside(root, path):
    real_root = os.path.realpath(root)
    real = os.path.realpath(path)
    return real == real_root or real.startswith(real_root + os.sep)


def exists_in_repo(root, rel):
    path = os.path.normpath(os.path.join(root, rel))
    if not inside(root, path):
        return False
    if any(c in rel for c in "*?["):
        import glob
        return bool(glob.glob(path))
    return os.path.exists(path)


def markdown_lines(path):
    """(line number, text) of the lines outside fenced code blocks."""
    in_fence = False
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, 1):
            if FENCE.match(line):
                in_fence = not in_fence
                continue
            if not in_fence:
                yield number, line


def check_link(root, md_rel, target, anchors_cache):
    if URL.match(target) or target.startswith("//"):
        return None
    path_part, _, anchor = target.partition("#")
    md_dir = os.path.dirname(os.path.join(root, md_rel))
    dest = os.path.normpath(os.path.join(md_dir, path_part)) if path_part else os.path.join(root, md_rel)
    if not inside(root, dest):
        return "link leaves the repository: %s" % target
    if not os.path.exists(dest):
        return "link to a missing file: %s" % target
    if anchor:
        if not dest.endswith(".md") or os.path.isdir(dest):
            return "anchor on a file that is not Markdown: %s" % target
        if dest not in anchors_cache:
            anchors_cache[dest] = anchors_of(dest)
        if anchor not in anchors_cache[dest]:
            return "link to a missing heading: %s" % target
    return None


def path_tokens(code):
    for raw in code.split():
        token = raw.strip(",;:()'\"").rstrip(".")
        if token.startswith("<") and token.endswith(">"):
            token = token[1:-1]
        if token:
            yield token


def check_code_token(root, token, top_level):
    if any(s in token for s in ("<", ">", "...", "$", "=", "://")):
        return None
    if re.match(r"^hpds(_node)?/.+\.hpp$", token):
        if not any(os.path.isfile(os.path.join(root, inc, token)) for inc in INCLUDE_DIRS):
            return "header not found under %s: %s" % (" or ".join(INCLUDE_DIRS), token)
        return None
    first = token.split("/", 1)[0]
    if "/" not in token or first not in top_level:
        return None
    missing = [t for t in expand_braces(token) if not exists_in_repo(root, t.rstrip("/"))]
    if missing:
        return "repository path not found: %s" % (token if len(missing) == 1 and missing[0] == token
                                                  else "%s (%s)" % (token, ", ".join(missing)))
    return None


def check_markdown(root, md_rel, top_level, anchors_cache):
    problems = []
    for number, line in markdown_lines(os.path.join(root, md_rel)):
        code_spans = list(INLINE_CODE.finditer(line))
        prose = INLINE_CODE.sub(lambda m: " " * len(m.group(0)), line)
        targets = [m.group(1) for m in LINK.finditer(prose)]
        ref = REF_DEF.match(prose)
        if ref:
            targets.append(ref.group(1))
        for target in targets:
            problem = check_link(root, md_rel, target, anchors_cache)
            if problem:
                problems.append("%s:%d: %s" % (md_rel, number, problem))
        for span in code_spans:
            for token in path_tokens(span.group(2)):
                problem = check_code_token(root, token, top_level)
                if problem:
                    problems.append("%s:%d: %s" % (md_rel, number, problem))
    return problems


def check_source(root, rel, top_level):
    """`.md` paths named in a code or build file; bare names (a tool's output file) are not repository paths."""
    problems = []
    if os.path.realpath(os.path.join(root, rel)) == os.path.realpath(__file__):
        return problems  # the fixtures below
    try:
        with open(os.path.join(root, rel), encoding="utf-8") as f:
            lines = list(f)
    except UnicodeDecodeError:
        return problems
    for number, line in enumerate(lines, 1):
        for m in MD_IN_SOURCE.finditer(line):
            token = m.group(0)
            if "/" not in token or token.split("/", 1)[0] not in top_level:
                continue
            if not exists_in_repo(root, token):
                problems.append("%s:%d: names a missing document: %s" % (rel, number, token))
    return problems


def check_repository(root):
    root = os.path.abspath(root)
    top_level = KNOWN_TOP_LEVEL | {e for e in os.listdir(root) if not is_skipped_dir(e)}
    anchors_cache = {}
    problems = []
    for rel in repo_files(root):
        name = os.path.basename(rel)
        if rel.endswith(".md"):
            problems += check_markdown(root, rel, top_level, anchors_cache)
        elif name in SOURCE_NAMES or name.endswith(SOURCE_SUFFIXES):
            problems += check_source(root, rel, top_level)
    return problems


# ----------------------------------------------------------------------------------------------------------------
# Self-test: fixture trees with planted references.

FIXTURE_FILES = {
    "config/hpds.yaml": "mode: scan\n",
    "hpds_core/src/a.cpp": "// see docs/guide.md; writes normal_accuracy.md into the output folder\n",
    "hpds_core/pcl/b.cpp": "// Measured: bench/README_QUALITY.md\n",
    "hpds_core/include/hpds/pipeline/Pipeline.hpp": "#pragma once\n",
    "launch/replay.launch": "<!-- see hpds_node/README_ROS.md and docs/guide.md -->\n",
    "docs/images/pic.png": "png",
    "Makefile": "# Sampling quality (docs/guide.md)\n",
    "docs/guide.md": """# Guide

## Quick start: ROS

## Offline replay: `hpds replay`

## Quick start: ROS

Back to [the README](../README.md#the-tool) and [its top](../README.md), [a section](#offline-replay-hpds-replay),
[the second one](#quick-start-ros-1), [a broken one](#quick-start-with-ros).
""",
    "README.md": """# Fixture

## The tool

![picture](docs/images/pic.png) and ![missing picture](docs/images/gone.png).
See [the guide](docs/guide.md), [its ROS part](docs/guide.md#quick-start-ros), [a wrong part](docs/guide.md#nope),
[a missing page](docs/missing.md), [the web](https://example.org/x.md), [outside](../outside.md).
[ref]: docs/also_missing.md

Paths: `config/hpds.yaml`, `config/other.yaml`, `hpds_core/{src,pcl}/`, `hpds_core/{src,gone}/`, `docs/*.md`,
`bench/*.cpp`, `build/demo/map.ply`, `hpds_core/src/<concern>/`, `make demo`, `hpds render x.ply -o pics`.
Headers: `hpds/pipeline/Pipeline.hpp`, `#include <hpds/hpds.hpp>`.

```sh
cat docs/not_checked_in_fences.md  [fenced](docs/not_checked.md) `config/not_checked.yaml`
```
""",
}

EXPECTED = {
    "README.md:5: link to a missing file: docs/images/gone.png",
    "README.md:6: link to a missing heading: docs/guide.md#nope",
    "README.md:7: link to a missing file: docs/missing.md",
    "README.md:7: link leaves the repository: ../outside.md",
    "README.md:8: link to a missing file: docs/also_missing.md",
    "README.md:10: repository path not found: config/other.yaml",
    "README.md:10: repository path not found: hpds_core/{src,gone}/ (hpds_core/gone/)",
    "README.md:11: repository path not found: bench/*.cpp",
    "README.md:12: header not found under hpds_core/include or hpds_node/include: hpds/hpds.hpp",
    "docs/guide.md:10: link to a missing heading: #quick-start-with-ros",
    "hpds_core/pcl/b.cpp:1: names a missing document: bench/README_QUALITY.md",
    "launch/replay.launch:1: names a missing document: hpds_node/README_ROS.md",
}


def write_tree(root, files):
    for rel, text in files.items():
        path = os.path.join(root, rel)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)


def self_test():
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        broken = os.path.join(tmp, "broken")
        write_tree(broken, FIXTURE_FILES)
        # A build folder inside the tree is not the repository's: its documents are not checked.
        write_tree(broken, {"build/x.md": "[gone](gone.md)\n"})
        found = set(check_repository(broken))
        for p in sorted(EXPECTED - found):
            failures.append("not reported: " + p)
        for p in sorted(found - EXPECTED):
            failures.append("reported but not planted: " + p)

        # The same tree with every planted problem repaired reports nothing.
        fixed = os.path.join(tmp, "repo")
        write_tree(fixed, FIXTURE_FILES)
        write_tree(fixed, {"docs/images/gone.png": "png", "docs/missing.md": "", "docs/also_missing.md": "",
                           "config/other.yaml": "", "hpds_core/gone/c.cpp": "", "bench/x.cpp": "",
                           "hpds_core/include/hpds/hpds.hpp": "", "bench/README_QUALITY.md": "",
                           "hpds_node/README_ROS.md": "", "outside.md": ""})
        with open(os.path.join(fixed, "README.md"), encoding="utf-8") as f:
            readme = f.read().replace("(docs/guide.md#nope)", "(docs/guide.md#offline-replay-hpds-replay)")
        readme = readme.replace("[outside](../outside.md)", "[inside](outside.md)")
        guide = FIXTURE_FILES["docs/guide.md"].replace("(#quick-start-with-ros)", "(#quick-start-ros)")
        write_tree(fixed, {"README.md": readme, "docs/guide.md": guide})
        for p in check_repository(fixed):
            failures.append("reported in the repaired tree: " + p)
    for f in failures:
        print("self-test: " + f)
    print("self-test: %s (%d planted problems)" % ("FAILED" if failures else "ok", len(EXPECTED)))
    return 1 if failures else 0


def main(argv):
    if len(argv) == 2 and argv[1] == "--self-test":
        return self_test()
    if len(argv) != 2 or not os.path.isdir(argv[1]):
        print(__doc__)
        return 2
    problems = check_repository(argv[1])
    for p in problems:
        print(p)
    print("%d broken reference(s) in the documentation" % len(problems) if problems
          else "every link and repository path named in the documentation exists")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
