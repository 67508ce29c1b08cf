#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Check that every reference a reader of the docs follows resolves inside the project.

Users have a clone of this repository and nothing beside it, so in README.md,
docs/*.md and every other markdown file of the repository (or the files given):

  * a markdown link or image to a relative path, [text](path) or [text](path#anchor),
    and a reference definition [label]: path, must name a file or folder inside the
    repository; an anchor (also [text](#anchor) in the same file) must be the
    GitHub-style slug of a heading of the target file (or an explicit id);
  * a path written as text or code (`docs/model.md`, `security.md`,
    `config/sim.yaml`) must exist, relative to the file's folder or to the
    repository's root, when it ends in .md or starts with a top-level folder of
    the repository;
  * nothing may send the reader to the project's private folder beside the
    source tree (`../shared/...`, `shared/spec/...`, `shared/papers/...`).

An allow-list (--allow) names the few lines where such a reference is meant, each
with its reason (the optional third-party sources the tests use when present).

Exit status: 0 when everything resolves, 1 with one line per problem
(FILE:LINE: what), 2 on a usage error. Python 3 standard library only.
"""
import argparse
import os
import re
import sys
import unicodedata

FENCE = re.compile(r"^ {0,3}(```+|~~~+)")
INLINE_CODE = re.compile(r"(`+)(.+?)\1")
# [text](target) and ![alt](target); target up to the first space or ')'.
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_DEF = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
HTML_ID = re.compile(r"<a\s+(?:name|id)=\"([^\"]+)\"", re.I)
LIST_ITEM = re.compile(r"^\s*(?:[-*+]|\d+[.)])\s")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")
SHARED = re.compile(r"(?:\.\./)+shared/|(?<![\w.-])shared/(?:spec|papers|notes|third_party|design)\b")
# A path written in text: word characters, dots, dashes and slashes.
PATH_TOKEN = re.compile(r"(?<![\w./~-])((?:\.\./|\./)*[\w.-]+(?:/[\w.-]+)*/?)")


def slug(text, seen):
    """GitHub's heading anchor: the rendered text lower-cased, punctuation dropped,
    spaces to dashes, and -1, -2 ... for repeats in one file."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)  # links keep their text
    text = re.sub(r"<[^>]+>", "", text)                       # inline HTML
    text = text.replace("`", "")
    text = re.sub(r"(\*+|(?<!\w)_+|_+(?!\w))", "", text)       # emphasis markers
    out = []
    for ch in text.lower():
        cat = unicodedata.category(ch)
        if ch in " -_" or cat[0] in "LNM" or cat == "Pc":
            out.append("-" if ch == " " else ch)
    base = "".join(out)
    s = base
    n = seen.get(base, 0)
    if n:
        s = f"{base}-{n}"
    seen[base] = n + 1
    return s


class Doc:
    """A markdown file split into lines of prose (code blocks marked)."""

    def __init__(self, path):
        self.path = path
        with open(path, encoding="utf-8") as f:
            self.lines = f.read().split("\n")
        self.code = [False] * len(self.lines)
        # Fenced blocks, and indented ones (4 spaces beyond the text of the list
        # item they are in, if any), as CommonMark has them; links in code are text.
        fence = None
        item_indent = 0  # where the text of the current list item starts; 0 outside lists
        prev_blank = True
        prev_code = False
        for i, line in enumerate(self.lines):
            m = FENCE.match(line)
            if fence:
                self.code[i] = True
                if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence):
                    fence = None
                continue
            if m:
                fence = m.group(1)
                self.code[i] = True
                continue
            blank = not line.strip()
            indent = len(line.expandtabs(4)) - len(line.expandtabs(4).lstrip())
            if not blank:
                if (prev_blank or prev_code) and indent >= item_indent + 4:
                    self.code[i] = True
                else:
                    item = LIST_ITEM.match(line)
                    if item:
                        item_indent = len(item.group(0))
                    elif indent == 0 and prev_blank:
                        item_indent = 0
            prev_code = self.code[i] or (blank and prev_code)
            prev_blank = blank
        self._anchors = None

    def anchors(self):
        if self._anchors is None:
            seen = {}
            a = set()
            for i, line in enumerate(self.lines):
                if self.code[i]:
                    continue
                m = HEADING.match(line)
                if m:
                    a.add(slug(m.group(2), seen))
                elif (line.strip() and i + 1 < len(self.lines) and not self.code[i + 1]
                      and re.match(r"^ {0,3}(=+|-+)\s*$", self.lines[i + 1])
                      and not LIST_ITEM.match(line) and i + 1 > 0):
                    a.add(slug(line.strip(), seen))
                for hid in HTML_ID.findall(line):
                    a.add(hid)
            self._anchors = a
        return self._anchors


def load_allow(path):
    """Lines `FILE | TEXT | REASON`: what this checker would report on a line of FILE
    that contains TEXT is allowed, for REASON. An entry that allows nothing is an
    error, so the list cannot outlive the lines it was written for."""
    allow = []
    if not path:
        return allow
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = [p.strip() for p in line.split("|")]
            if len(parts) != 3 or not all(parts):
                sys.exit(f"{path}:{n}: expected 'FILE | TEXT | REASON'")
            allow.append({"file": parts[0], "text": parts[1], "where": f"{path}:{n}", "used": False})
    return allow


class Checker:
    def __init__(self, root, top_dirs, allow):
        self.root = os.path.realpath(root)
        self.top_dirs = top_dirs
        self.allow = allow
        self.docs = {}
        self.problems = []

    def doc(self, path):
        path = os.path.realpath(path)
        if path not in self.docs:
            self.docs[path] = Doc(path)
        return self.docs[path]

    def rel(self, path):
        return os.path.relpath(path, self.root)

    def report(self, doc, i, what):
        name = self.rel(doc.path)
        for a in self.allow:
            if a["file"] == name and a["text"] in doc.lines[i]:
                a["used"] = True
                return
        self.problems.append(f"{name}:{i + 1}: {what}")

    def inside(self, path):
        real = os.path.realpath(path)
        return real == self.root or real.startswith(self.root + os.sep)

    def check_target(self, doc, i, target):
        if not target or SCHEME.match(target) or target.startswith("/"):
            return  # a web address, mail, or an absolute path on the machine
        path, _, anchor = target.partition("#")
        if path:
            full = os.path.normpath(os.path.join(os.path.dirname(doc.path), path))
            if not self.inside(full):
                self.report(doc, i, f"link '{target}' leaves the repository: a user's clone has nothing there")
                return
            if not os.path.exists(full):
                self.report(doc, i, f"link '{target}': no such file in the repository")
                return
        else:
            full = doc.path
        if anchor:
            if not full.endswith(".md") or os.path.isdir(full):
                return
            if anchor not in self.doc(full).anchors():
                self.report(doc, i, f"link '{target}': {self.rel(full)} has no heading with anchor '#{anchor}'")

    def check_mention(self, doc, i, token):
        token = token.rstrip(".")
        if "..." in token or "*" in token or token.startswith("~"):
            return
        first = token.lstrip("./").split("/")[0]
        is_md = token.endswith(".md")
        if not is_md and not ("/" in token and first in self.top_dirs and not token.startswith("..")):
            return
        here = os.path.normpath(os.path.join(os.path.dirname(doc.path), token))
        at_root = os.path.normpath(os.path.join(self.root, token))
        for cand in (here, at_root):
            if self.inside(cand) and os.path.exists(cand):
                return
        self.report(doc, i, f"'{token}' is named but is not a file of the repository")

    def check_shared(self, doc, i, line):
        if SHARED.search(line):
            self.report(doc, i, "refers to the private folder beside the source tree (../shared, shared/spec, "
                                "shared/papers ...), which users do not have: point at docs/ instead")

    def check(self, path):
        doc = self.doc(path)
        for i, line in enumerate(doc.lines):
            self.check_shared(doc, i, line)
            if doc.code[i]:
                continue
            m = REF_DEF.match(line)
            if m:
                self.check_target(doc, i, m.group(1))
                continue
            prose = line
            spans = [s.group(2) for s in INLINE_CODE.finditer(line)]
            prose = INLINE_CODE.sub(" ", line)
            for lm in LINK.finditer(prose):
                self.check_target(doc, i, lm.group(1))
            text = LINK.sub(" ", prose)
            text = re.sub(r"https?://\S+", " ", text)
            for chunk in spans + [text]:
                for tm in PATH_TOKEN.finditer(chunk):
                    if not chunk[tm.end():tm.end() + 1] == "*":  # a pattern, `regress-*`
                        self.check_mention(doc, i, tm.group(1))

    def stale_allow(self):
        for a in self.allow:
            if not a["used"]:
                self.problems.append(f"{a['where']}: allow-list entry matches nothing "
                                     f"('{a['text']}' in {a['file']}): remove it")


SOURCE_SUFFIXES = (".cpp", ".hpp", ".h", ".c", ".lcm", ".yaml", ".yml", ".txt", ".cmake", ".in", ".sh",
                   ".py", ".service", ".conf", ".md")


def source_files(root, skip):
    """Every text file of the project a user reads beside the docs: code (its messages
    and comments), configuration, build files; not build trees, not `skip`."""
    for here, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not d.startswith("build")
                         and not os.path.exists(os.path.join(here, d, "CMakeCache.txt"))
                         and os.path.realpath(os.path.join(here, d)) not in skip)
        for f in sorted(files):
            if f.endswith(SOURCE_SUFFIXES) or f == "CMakeLists.txt":
                yield os.path.join(here, f)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default=os.path.join(os.path.dirname(__file__), "..", ".."),
                    help="the repository's root (default: two folders above this script)")
    ap.add_argument("--allow", help="allow-list, one 'FILE | TEXT | REASON' a line")
    ap.add_argument("--sources", action="store_true",
                    help="check only for references to the private folder, in every source, config and "
                         "build file under the root (markdown and this checker's folder excepted)")
    ap.add_argument("files", nargs="*", help="markdown files (default: every *.md of the repository: "
                                             "README.md, docs/ and the notes beside the code)")
    args = ap.parse_args()
    root = os.path.realpath(args.root)
    here = os.path.realpath(os.path.dirname(os.path.abspath(__file__)))  # the checker and its fixture
    if args.sources:
        c = Checker(root, set(), load_allow(args.allow))
        n = 0
        for f in source_files(root, {here}):
            if f.endswith(".md"):
                continue  # the markdown check's
            n += 1
            try:
                doc = c.doc(f)
            except UnicodeDecodeError:
                continue
            for i, line in enumerate(doc.lines):
                c.check_shared(doc, i, line)
        c.stale_allow()
        for p in c.problems:
            print(p)
        print(f"{n} file(s): {len(c.problems)} reference(s) to the private folder" if c.problems else
              f"{n} file(s): none refers to the private folder beside the source tree")
        return 1 if c.problems else 0
    files = args.files or [f for f in source_files(root, {here}) if f.endswith(".md")]
    for f in files:
        if not os.path.isfile(f):
            print(f"{f}: no such file", file=sys.stderr)
            return 2
    top_dirs = {d for d in os.listdir(root)
                if os.path.isdir(os.path.join(root, d)) and not d.startswith(".") and d != "build"}
    c = Checker(root, top_dirs, load_allow(args.allow))
    for f in files:
        c.check(f)
    c.stale_allow()
    for p in c.problems:
        print(p)
    if c.problems:
        print(f"{len(c.problems)} dangling reference(s) in {len(files)} file(s)")
        return 1
    print(f"{len(files)} file(s): every reference resolves inside the repository")
    return 0


if __name__ == "__main__":
    sys.exit(main())
