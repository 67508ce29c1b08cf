#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""A man page (roff, man macros) from the project's own Markdown docs.

The file-format pages (cpmd.yaml(5), cpm-model(5)) are generated at build
time from docs/daemon.md and docs/model-file.md, so the page and the doc are
one text. Handles what those docs use: headings, paragraphs, lists, tables
(as tagged paragraphs), fenced and indented code, inline code, bold,
emphasis and links. pandoc would do it, but Debian's build machines do not
have it by default; this is the subset we need.

  md2man.py --name NAME --section 5 --summary TEXT [--heading PREFIX]
            [--example TITLE=FILE]... [--see-also TEXT] [--version V] DOC.md
"""
import argparse
import datetime
import os
import re
import sys


def escape(text):
    """Roff-safe text: backslashes, a leading dot or quote, and non-ASCII
    characters as groff's \\[uXXXX] (no preconv needed)."""
    text = text.replace("\\", "\\e")
    text = "".join(c if ord(c) < 128 else f"\\[u{ord(c):04X}]" for c in text)
    if text.startswith((".", "'")):
        text = "\\&" + text
    return text


def inline(text):
    """Markdown inline markup to roff fonts; links keep their text."""
    out = []
    # Code spans first: their content is literal.
    for k, part in enumerate(re.split(r"(`[^`]*`)", text)):
        if k % 2:
            out.append("\\fB" + escape(part[1:-1]).replace("-", "\\-") + "\\fR")
            continue
        part = escape(part)
        part = re.sub(r"\[([^\]]+)\]\([^)]+\)", r"\1", part)
        part = re.sub(r"\*\*([^*]+)\*\*", r"\\fB\1\\fR", part)
        part = re.sub(r"(?<![\w*])\*([^*\s][^*]*)\*(?![\w*])", r"\\fI\1\\fR", part)
        part = part.replace("\\e|", "|")  # \| in a table cell is a literal bar
        out.append(part)
    line = "".join(out)
    return "\\&" + line if line.startswith((".", "'")) else line


def select(lines, prefix):
    """The lines of the section whose heading starts with `prefix` (without the heading)."""
    for i, line in enumerate(lines):
        m = re.match(r"(#+)\s+(.*)", line)
        if m and m.group(2).startswith(prefix):
            level = len(m.group(1))
            body = []
            for nxt in lines[i + 1:]:
                n = re.match(r"(#+)\s", nxt)
                if n and len(n.group(1)) <= level:
                    break
                body.append(nxt)
            return body
    sys.exit(f"md2man: no heading starting with '{prefix}'")


def table_rows(block):
    rows = []
    for line in block:
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]
        if all(re.fullmatch(r":?-+:?", c) for c in cells if c):
            continue
        rows.append(cells)
    return rows


def convert(lines):
    """Markdown lines to roff lines (the body: after .TH and NAME)."""
    out = []
    i = 0
    in_section = False
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        m = re.match(r"(#+)\s+(.*)", line)
        if m:
            level, title = len(m.group(1)), re.sub(r"`", "", m.group(2))
            if level <= 2:
                out.append(".SH " + escape(title.upper()))
                in_section = True
            else:
                out.append(".SS " + escape(title))
            i += 1
            continue
        if not in_section:
            out.append(".SH DESCRIPTION")
            in_section = True
        if not stripped:
            i += 1
            continue
        if stripped.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith("```"):
                j += 1
            out += [".PP", ".RS 4", ".nf"] + [escape(l) for l in lines[i + 1:j]] + [".fi", ".RE"]
            i = j + 1
            continue
        if line.startswith("    "):
            j = i
            while j < len(lines) and (lines[j].startswith("    ") or not lines[j].strip()):
                j += 1
            block = [l[4:] for l in lines[i:j]]
            while block and not block[-1].strip():
                block.pop()
            out += [".PP", ".RS 4", ".nf"] + [escape(l) for l in block] + [".fi", ".RE"]
            i = j
            continue
        if stripped.startswith("|"):
            j = i
            while j < len(lines) and lines[j].strip().startswith("|"):
                j += 1
            rows = table_rows(lines[i:j])
            header, body = rows[0], rows[1:]
            for cells in body:
                out += [".TP", inline(cells[0])]
                rest = [f"{inline(header[k])}: {inline(c)}" if k < len(header) - 1 else inline(c)
                        for k, c in enumerate(cells[1:], start=1) if c]
                out.append("; ".join(rest))
            i = j
            continue
        item = re.match(r"(\s*)([-*]|\d+\.)\s+(.*)", line)
        if item:
            bullet = "\\(bu" if item.group(2) in "-*" else item.group(2)
            text = [item.group(3)]
            i += 1
            while i < len(lines) and lines[i].strip() and not re.match(r"\s*([-*]|\d+\.)\s+", lines[i]) \
                    and not lines[i].strip().startswith(("|", "```", "#")):
                text.append(lines[i].strip())
                i += 1
            out += [f".IP {bullet} 4", inline(" ".join(text))]
            continue
        text = []
        while i < len(lines) and lines[i].strip() and not lines[i].startswith("    ") \
                and not re.match(r"(#+\s|\s*([-*]|\d+\.)\s+|\s*\||\s*```)", lines[i]):
            text.append(lines[i].strip())
            i += 1
        out += [".PP", inline(" ".join(text))]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("doc")
    ap.add_argument("--name", required=True)
    ap.add_argument("--section", required=True)
    ap.add_argument("--summary", required=True, help="the NAME line's description")
    ap.add_argument("--heading", help="only the section whose heading starts with this")
    ap.add_argument("--example", action="append", default=[], help="TITLE=FILE: a file shown verbatim in EXAMPLES")
    ap.add_argument("--see-also", default="")
    ap.add_argument("--version", default="")
    a = ap.parse_args()

    with open(a.doc, encoding="utf-8") as f:
        lines = f.read().splitlines()
    if a.heading:
        lines = select(lines, a.heading)
    elif lines and lines[0].startswith("# "):
        lines = lines[1:]  # the title: the NAME line says it
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    date = datetime.datetime.fromtimestamp(int(epoch), datetime.timezone.utc) if epoch else datetime.datetime.now()
    page = [f'.\\" Generated by tools/man/md2man.py from {os.path.basename(a.doc)}: edit that file, not this one.',
            f'.TH {a.name.upper()} {a.section} "{date.strftime("%B %Y")}" "cpmd {a.version}" "File Formats Manual"',
            ".SH NAME", f"{escape(a.name)} \\- {escape(a.summary)}"]
    page += convert(lines)
    if a.example:
        page.append(".SH EXAMPLES")
        for ex in a.example:
            title, path = ex.split("=", 1)
            with open(path, encoding="utf-8") as f:
                body = f.read().splitlines()
            page += [".SS " + escape(title), ".RS 4", ".nf"] + [escape(l) for l in body] + [".fi", ".RE"]
    if a.see_also:
        page += [".SH SEE ALSO", inline(a.see_also)]
    sys.stdout.write("\n".join(page) + "\n")


if __name__ == "__main__":
    main()
