#!/usr/bin/env python3
"""Lists C++ functions longer than N lines in the given files.

  tools/check-function-length.py [--max 120] FILE...

A function is a brace block opened at namespace or class scope whose header (the text since the
previous ';', '{' or '}' at that scope) ends with ')' plus optional qualifiers (const, noexcept,
override, a trailing return type, a constructor's initializer list). Lambdas and blocks inside a
function count towards that function. Comments, string and character literals are blanked first,
so braces in them do not count. Good enough for this tree's style; not a C++ parser.
Exit status 1 when a function is over the limit, 0 otherwise."""
import argparse
import re
import sys

SCOPE_WORDS = re.compile(r"\b(namespace|class|struct|union|enum)\b")


def blank(text):
    """The text with comments and literals replaced by spaces (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not text[i - 1].isalnum()):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            end = ")" + m.group(1) + '"'
            j = text.find(end, i + m.end())
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c in "\"'":
            # A digit separator (1'000) is not a character literal.
            if c == "'" and i > 0 and text[i - 1].isalnum() and i + 1 < n and text[i + 1].isalnum():
                out.append(" ")
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(" " * (j - i))
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def function_name(header):
    """The name before the parameter list of a function header, or None."""
    h = " ".join(header.split())
    h = re.sub(r"^\s*(template\s*<[^{};]*>\s*)", "", h)
    # Drop a constructor's initializer list: ") : a_(x), b_(y)".
    depth = 0
    for k, ch in enumerate(h):
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == ":" and depth == 0 and (k + 1 >= len(h) or h[k + 1] != ":") and (
                k == 0 or h[k - 1] != ":"):
            if ")" in h[:k]:
                h = h[:k]
                break
    h = h.strip()
    if not re.search(r"\)\s*(const|noexcept|override|final|mutable|->[^()]*|&|&&|\s)*$", h):
        return None
    if re.match(r"^(if|for|while|switch|catch|return)\b", h) or "=" in h.split("(")[0]:
        return None
    m = re.search(r"([~A-Za-z_][\w:~<>,\s]*?(operator\s*[^\s(]+)?)\s*\(", h)
    if not m:
        return None
    name = m.group(1).split()[-1] if m.group(1).split() else m.group(1)
    return name


def functions(path):
    """(name, first line, line count) of each function defined at namespace or class scope."""
    text = blank(open(path, encoding="utf-8", errors="replace").read())
    stack = []  # per open brace: "scope" or "function" or "block"
    header_start = 0
    found = []
    line = 1
    open_fn = None  # (name, start line, depth)
    for i, ch in enumerate(text):
        if ch == "\n":
            line += 1
        elif ch == ";" and (not stack or stack[-1] == "scope"):
            header_start = i + 1
        elif ch == "{":
            if open_fn is not None:
                stack.append("block")
                continue
            header = text[header_start:i]
            header = re.sub(r"^\s*#.*$", "", header, flags=re.M)
            # Only the header's last statement-ish part: after any access specifier.
            header = re.split(r"\b(?:public|private|protected)\s*:(?!:)", header)[-1]
            name = function_name(header)
            if name and not SCOPE_WORDS.search(header.split("(")[0]):
                start = line - header[header.rfind(")"):].count("\n") if ")" in header else line
                open_fn = (name, start, len(stack))
                stack.append("function")
            else:
                stack.append("scope")
            header_start = i + 1
        elif ch == "}":
            kind = stack.pop() if stack else "scope"
            if kind == "function" and open_fn is not None and len(stack) == open_fn[2]:
                found.append((open_fn[0], open_fn[1], line - open_fn[1] + 1))
                open_fn = None
            if open_fn is None:
                header_start = i + 1
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max", type=int, default=120, help="longest allowed function, lines")
    ap.add_argument("--all", action="store_true", help="list every function, longest first")
    ap.add_argument("files", nargs="+")
    a = ap.parse_args()
    rows = []
    for f in a.files:
        rows += [(n, f, name, start) for name, start, n in functions(f)]
    rows.sort(reverse=True)
    over = [r for r in rows if r[0] > a.max]
    for n, f, name, start in rows if a.all else over:
        print(f"{f}:{start}: {name} {n} lines")
    if not a.all:
        print(f"{len(over)} function(s) over {a.max} lines in {len(a.files)} file(s)",
              file=sys.stderr)
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
