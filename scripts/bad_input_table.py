#!/usr/bin/env python3
"""Writes docs/bad_input.md: every bad-input class the test suite tries, what the user sees
(the message the test requires) and the test that proves it, read from the tests themselves so
the table cannot drift from them.

  scripts/bad_input_table.py            print the table
  scripts/bad_input_table.py --write    rewrite docs/bad_input.md

A row is one assertion that requires an error message: require_parse_error / require_io_error
(io readers), CHECK_INVALID, CHECK_THROWS_WITH / REQUIRE_THROWS_WITH with Catch::Contains, a
`why` string checked with Contains (validators), or a CLI run's output checked with find() in a
test case about refusing bad input. The class is the comment just above the assertion, else the
test case's name (and section).
"""
import argparse
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ASSERT = re.compile(r"\b(require_parse_error|require_io_error|CHECK_INVALID|CHECK_THROWS_WITH|"
                    r"REQUIRE_THROWS_WITH|CHECK_THAT|REQUIRE_THAT|CHECK|REQUIRE)\s*\(")
ERRORISH = re.compile(r"refus|reject|report|bad|error|invalid|missing|malformed|fail|wrong|"
                      r"corrupt|degenerate|too few|unknown|limit|clear", re.I)
STRING = re.compile(r'"((?:[^"\\]|\\.)*)"')


def statement(lines, i):
    """The assertion starting at line i, joined up to its closing ';'."""
    text, depth, j = "", 0, i
    while j < len(lines):
        text += lines[j].strip() + " "
        code = STRING.sub('""', lines[j])  # a parenthesis inside a string literal is text
        depth += code.count("(") - code.count(")")
        if depth <= 0 and ";" in code:
            break
        j += 1
    return text, j


def message(kind, text):
    """The message fragment the assertion requires, or None when it is not an error check."""
    if kind in ("require_parse_error", "CHECK_INVALID"):
        s = STRING.findall(text)
        return s[-1] if s else None
    if kind == "require_io_error":
        return "(I/O error naming the path)"
    if "Contains(" in text:
        s = re.findall(r'Contains\(\s*((?:"(?:[^"\\]|\\.)*"\s*)+)', text)
        if s:
            return " ... ".join("".join(STRING.findall(x)) for x in s)
    if kind in ("CHECK", "REQUIRE") and ".find(" in text and "npos" in text and "!=" in text:
        s = re.findall(r'(?:output|err|stderr)\w*\.find\(\s*"((?:[^"\\]|\\.)*)"', text)
        return s[0] if s else None
    return None


def rows():
    out = []
    for dirpath, _, files in sorted(os.walk(os.path.join(ROOT, "tests"))):
        for f in sorted(files):
            if not f.endswith(".cpp"):
                continue
            path = os.path.join(dirpath, f)
            rel = os.path.relpath(path, ROOT)
            lines = open(path, encoding="utf-8").read().split("\n")
            case, section, comment, prev_comment, i = "", "", "", False, 0
            while i < len(lines):
                line = lines[i]
                stripped = line.strip()
                m = re.match(r'\s*TEST_CASE\(\s*"((?:[^"\\]|\\.)*)"', line)
                if m:
                    case, section, comment = m.group(1), "", ""
                m = re.match(r'\s*SECTION\(\s*"((?:[^"\\]|\\.)*)"', line)
                if m:
                    section, comment = m.group(1), ""
                if stripped.startswith("//"):
                    c = stripped.lstrip("/ ").rstrip()
                    comment = (comment + " " + c).strip() if prev_comment else c
                    prev_comment = True
                    i += 1
                    continue
                prev_comment = False
                if not stripped:
                    comment = ""  # a comment describes the statements below it, to a blank line
                a = ASSERT.search(line)
                if not (a and case):
                    i += 1
                    continue
                text, j = statement(lines, i)
                kind = a.group(1)
                msg = message(kind, text)
                if kind in ("CHECK", "REQUIRE", "CHECK_THAT", "REQUIRE_THAT") and \
                        not ERRORISH.search(case + " " + comment):
                    msg = None
                if msg:
                    what = comment or (f"{case}: {section}" if section else case)
                    out.append((rel, i + 1, case, what, msg))
                    comment = ""  # a comment names the first error check below it
                i = j + 1
    return out



def table(rs):
    area_of = lambda rel: rel.split("/")[1]
    lines = [
        "# Bad input: what geodrift does with it",
        "",
        "Every row is a bad-input class the test suite tries, the message the user then sees "
        "(the fragment the test requires; commands print it as `geodrift <command>: error: ...` "
        "and exit non-zero without writing their outputs), and the test that proves it. The "
        "table is generated from the tests:",
        "",
        "```sh",
        "scripts/bad_input_table.py --write    # rewrites this file",
        "```",
        "",
        "Beyond these, every parser is fuzzed (docs/fuzzing.md) and its corpus replayed by the "
        "test suite; size limits are in BENCHMARKS.md \"Limits\".",
        "",
    ]
    areas = {}
    for r in rs:
        areas.setdefault(area_of(r[0]), []).append(r)
    lines.append(f"{len(rs)} classes in {len(areas)} areas.")
    lines.append("")
    n = 0
    for area in sorted(areas):
        lines += [f"## {area}", "", "| # | input | what the user sees | test |", "|---|---|---|---|"]
        for rel, ln, case, what, msg in areas[area]:
            n += 1
            cell = lambda s: s.replace("|", "\\|").replace("\\\"", "\"")
            lines.append(f"| {n} | {cell(what)} | `{cell(msg)}` | [{os.path.basename(rel)}:{ln}]"
                         f"(../{rel}#L{ln}) |")
        lines.append("")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="rewrite docs/bad_input.md")
    a = ap.parse_args()
    text = table(rows())
    if a.write:
        with open(os.path.join(ROOT, "docs", "bad_input.md"), "w", encoding="utf-8") as f:
            f.write(text)
    else:
        sys.stdout.write(text)


if __name__ == "__main__":
    main()
