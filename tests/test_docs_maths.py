"""``docs/maths.md`` — the project's own mathematical documentation — and the citations of it.

* The page itself: sections ``## 1.`` … ``## 9.`` with the expected subjects, equations tagged
  ``\\tag{N.M}`` inside section N and numbered 1, 2, … within each section, a numbered
  "Notes on the thesis" list, every module path it names exists, and it is self-contained (it
  cites no file outside the repository).
* Citations of it, in the ``.py`` files under ``stiefel/ objectives/ mesh/ stiefel_cmm/ bench/`` (and
  ``tests/``), in ``README.md``, ``docs/*.md`` and the notebooks: ``docs/maths.md §N`` (also
  ``§N–M``, ``§N, §M``), ``docs/maths.md note N``, ``docs/maths.md#anchor`` and an equation
  ``eq. N.M`` / ``eq. (N.M)`` right after such a citation must all exist in the page (an equation
  must belong to a cited section).
* Nothing in the repository's code, README or notebooks points at the specification outside
  the repository (``../shared/docs/MATH.md``): users who clone the repository do not have it.

Pure text checks: no JAX, fast. A failure lists every offending ``file:line`` with the reference.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "maths.md"
DOC_NAME = "docs/maths.md"
CODE_DIRS = ("stiefel", "objectives", "mesh", "stiefel_cmm", "bench")
TEXT_SUFFIXES = {".py", ".md", ".txt", ".json", ".toml", ".cfg", ".ini", ".rst", ".ipynb", ".yaml", ".yml", ".sh"}

# §N of docs/maths.md: a word each section title must contain (the numbering is shared with the
# specification the code cited before, so citations can be retargeted without renumbering).
EXPECTED_SECTIONS = {
    1: "generalised stiefel manifold",
    2: "sequential optimisation",
    3: "line search",
    4: "objectives",
    5: "admm",
    6: "fast approximation",
    7: "mesh operators",
    8: "evaluating bases",
    9: "second order",
}
NOTES_HEADING = "Notes on the thesis"

DASH = r"[–—-]"
SEC_REF = re.compile(rf"§{{1,2}}\s?(\d+)(?:\s?{DASH}\s?§?\s?(\d+))?")
SEC_SEP = re.compile(r"\s?(?:,|and|&|/)\s?(?=§)")
NOTE_REF = re.compile(rf"[\s,]*(?:and\s+)?(?:the\s+)?notes?\s+(\d+)(?:\s?{DASH}\s?(\d+))?")
NOTE_MORE = re.compile(rf"\s?(?:,|and|&)\s?(\d+)(?:\s?{DASH}\s?(\d+))?(?![.\d])")
ANCHOR = re.compile(r"#([\w\-]+)")
# an equation reference right after the section references:
# "§1 (eq. 1.3)", "§1, eq. (1.3)", "§1–3 (eqs. (1.6)–(1.7))"
EQ_NEXT = re.compile(r"[\s,:]*\(?\s?eq(?:s|n|ns)?\.?\s?"
                     r"((?:\(?\d+(?:\.\d+)+\)?(?:\s?(?:" + DASH + r"|,|and|&)\s?)?)+)", re.I)
EQ_NUMBER = re.compile(r"(?<![\d.])(\d+)\.(\d+)(?![.\d])")
ERRATA = re.compile(r"[\s,;]*(?:and\s+)?(?:the\s+)?errat", re.I)


# --------------------------------------------------------------------------------------------
# the page
# --------------------------------------------------------------------------------------------


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _parse_doc():
    """``(sections {N: title}, tags {(N, M): line}, notes {K}, anchors {slug}, problems [str])``."""
    assert DOC.is_file(), f"{DOC_NAME} is missing: it is the mathematics every docstring cites"
    sections: dict[int, str] = {}
    tags: dict[tuple[int, int], int] = {}
    order: dict[int, list[int]] = {}
    notes: list[int] = []
    anchors: set[str] = set()
    problems: list[str] = []
    current = None  # section number, "notes", or None (preamble)
    in_fence = False
    for lineno, line in enumerate(DOC.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            in_fence = not in_fence
            continue
        if in_fence:
            continue
        heading = re.match(r"^(#{1,6})\s+(.*?)\s*$", line)
        if heading:
            anchors.add(_slug(heading.group(2)))
            if len(heading.group(1)) == 2:
                numbered = re.match(r"^(\d+)\.\s+(.+)$", heading.group(2))
                if numbered:
                    current = int(numbered.group(1))
                    if current in sections:
                        problems.append(f"{DOC_NAME}:{lineno}: section §{current} appears twice")
                    sections[current] = numbered.group(2)
                elif heading.group(2) == NOTES_HEADING:
                    current = "notes"
                else:
                    current = None
            continue
        for m in re.finditer(r"\\tag\{([^}]*)\}", line):
            value = m.group(1).strip()
            parts = re.fullmatch(r"(\d+)\.(\d+)", value)
            if not parts:
                problems.append(f"{DOC_NAME}:{lineno}: \\tag{{{value}}} is not of the form N.M")
                continue
            key = (int(parts.group(1)), int(parts.group(2)))
            if key in tags:
                problems.append(f"{DOC_NAME}:{lineno}: equation ({value}) is tagged twice (first on line {tags[key]})")
            tags[key] = lineno
            if key[0] != current:
                problems.append(f"{DOC_NAME}:{lineno}: equation ({value}) sits in "
                                f"{'§' + str(current) if isinstance(current, int) else current or 'the preamble'}, "
                                f"not in §{key[0]}")
            order.setdefault(key[0], []).append(key[1])
        if current == "notes":
            item = re.match(r"^(\d+)\.\s", line)
            if item:
                notes.append(int(item.group(1)))
    for sec, numbers in order.items():
        if numbers != list(range(1, len(numbers) + 1)):
            problems.append(f"{DOC_NAME}: the equations of §{sec} are numbered {numbers}; expected 1, 2, … in order")
    if notes != list(range(1, len(notes) + 1)):
        problems.append(f"{DOC_NAME}: the '{NOTES_HEADING}' items are numbered {notes}; expected 1, 2, … in order")
    return sections, tags, set(notes), anchors, problems


@pytest.fixture(scope="module")
def doc():
    sections, tags, notes, anchors, problems = _parse_doc()
    return {"sections": sections, "tags": tags, "notes": notes, "anchors": anchors, "problems": problems}


def test_doc_sections_equations_and_notes_are_consistent(doc):
    """§1–§9 with their subjects, well-formed and well-placed equation tags, a numbered notes list."""
    problems = list(doc["problems"])
    sections = doc["sections"]
    for number, subject in EXPECTED_SECTIONS.items():
        title = sections.get(number)
        if title is None:
            problems.append(f"{DOC_NAME}: no heading '## {number}. ' (expected the section on {subject!r})")
        elif subject not in title.lower():
            problems.append(f"{DOC_NAME}: '## {number}. {title}' should be the section on {subject!r}: the "
                            "numbering must stay that of the citations in the code")
    extra = sorted(set(sections) - set(EXPECTED_SECTIONS))
    if extra:
        problems.append(f"{DOC_NAME}: unexpected numbered sections {extra}")
    missing_eqs = [n for n in EXPECTED_SECTIONS if not any(sec == n for sec, _ in doc["tags"])]
    if missing_eqs:
        problems.append(f"{DOC_NAME}: sections without any numbered equation: {missing_eqs}")
    if not doc["notes"]:
        problems.append(f"{DOC_NAME}: no numbered items under '## {NOTES_HEADING}'")
    if problems:
        pytest.fail("docs/maths.md is inconsistent:\n  " + "\n  ".join(problems), pytrace=False)


def test_doc_names_existing_modules_in_every_section():
    """Each section says which modules implement it, and every module path the page names exists."""
    text = DOC.read_text(encoding="utf-8")
    parts = re.split(r"^## ", text, flags=re.M)
    problems = []
    for part in parts[1:]:
        head = part.splitlines()[0]
        numbered = re.match(r"(\d+)\.", head)
        paths = re.findall(r"`((?:stiefel|objectives|mesh|stiefel_cmm.cli|bench|tests)/[\w/]+\.py)`", part)
        if numbered and not paths:
            problems.append(f"§{numbered.group(1)} names no implementing module (`package/module.py`)")
        for path in paths:
            if not (ROOT / path).is_file():
                problems.append(f"§{head.split()[0].rstrip('.')} names `{path}`, which does not exist")
    if problems:
        pytest.fail("docs/maths.md and the code disagree:\n  " + "\n  ".join(problems), pytrace=False)


def test_doc_is_self_contained():
    """The page cites nothing outside the repository (no MATH.md, no ../shared path)."""
    bad = [f"{DOC_NAME}:{i}: {line.strip()}" for i, line in enumerate(DOC.read_text(encoding="utf-8").splitlines(), 1)
           if "MATH.md" in line or "shared/" in line]
    if bad:
        pytest.fail("docs/maths.md must be self-contained; it mentions files users do not have:\n  " + "\n  ".join(bad),
                    pytrace=False)


# --------------------------------------------------------------------------------------------
# the citations
# --------------------------------------------------------------------------------------------


def _files_citing():
    """Files whose citations of docs/maths.md are checked (code, tests, README, docs, notebooks)."""
    files = []
    for d in CODE_DIRS + ("tests",):
        files += sorted((ROOT / d).rglob("*.py"))
    files += [ROOT / "README.md"]
    files += sorted(p for p in (ROOT / "docs").glob("*.md") if p != DOC)
    files += sorted((ROOT / "notebooks").glob("*.ipynb"))
    here = Path(__file__).resolve()
    return [p for p in files if p.is_file() and p.resolve() != here and ".ipynb_checkpoints" not in p.parts]


def _blobs(path: Path):
    """``(label(offset) -> 'file:line', text)`` pieces of a file: the whole file, or each notebook cell."""
    rel = path.relative_to(ROOT).as_posix()
    if path.suffix == ".ipynb":
        try:
            cells = json.loads(path.read_text(encoding="utf-8")).get("cells", [])
        except json.JSONDecodeError as exc:
            pytest.fail(f"{rel}: not valid notebook JSON ({exc})")
        for i, cell in enumerate(cells):
            src = cell.get("source", "")
            text = "".join(src) if isinstance(src, list) else str(src)
            yield (lambda off, i=i, text=text: f"{rel} (cell {i}, line {text.count(chr(10), 0, off) + 1})"), text
    else:
        text = path.read_text(encoding="utf-8", errors="replace")
        yield (lambda off, text=text: f"{rel}:{text.count(chr(10), 0, off) + 1}"), text


def _expand(first: str, last: str | None) -> list[int]:
    a = int(first)
    b = int(last) if last else a
    return list(range(a, b + 1)) if a <= b else [a, b]


def _parse_citation(tail: str):
    """The references right after 'docs/maths.md' in ``tail`` (whitespace collapsed).

    Returns ``(sections, notes, anchor, equations, problems, end)``, ``end`` the length of ``tail``
    the references took.
    """
    sections: list[int] = []
    notes: list[int] = []
    equations: list[tuple[int, int]] = []
    problems: list[str] = []
    anchor = None
    pos = 0
    m = ANCHOR.match(tail)
    if m:
        anchor = m.group(1)
        pos = m.end()
    m = re.compile(r"[\s,:]*(?:,\s?)?").match(tail, pos)
    start = m.end()
    m = SEC_REF.match(tail, start)
    while m:
        sections += _expand(m.group(1), m.group(2))
        pos = m.end()
        sep = SEC_SEP.match(tail, pos)
        if not sep:
            break
        m = SEC_REF.match(tail, sep.end())
    if not sections and re.match(r"[\s,:]*§", tail):
        problems.append("a '§' that is not followed by a section number")
    m = NOTE_REF.match(tail, pos)
    if m:
        notes += _expand(m.group(1), m.group(2))
        pos = m.end()
        more = NOTE_MORE.match(tail, pos)
        while more:
            notes += _expand(more.group(1), more.group(2))
            pos = more.end()
            more = NOTE_MORE.match(tail, pos)
    if ERRATA.match(tail, pos):
        problems.append("it cites errata; docs/maths.md has no errata — cite its numbered "
                        "'Notes on the thesis' as 'docs/maths.md note N' (or a section)")
    eq = EQ_NEXT.match(tail, pos)
    if eq:
        for num in EQ_NUMBER.finditer(eq.group(1)):
            equations.append((int(num.group(1)), int(num.group(2))))
        pos = eq.end()
    return sections, notes, anchor, equations, problems, pos


def _citation_problems(doc) -> list[str]:
    sections, tags, notes, anchors = doc["sections"], doc["tags"], doc["notes"], doc["anchors"]
    have = f"§{min(sections)}–§{max(sections)}" if sections else "none"
    problems = []
    for path in _files_citing():
        for where, text in _blobs(path):
            for m in re.finditer(r"(?<![\w.])(?:docs/)?maths\.md", text):
                loc = where(m.start())
                if not m.group(0).startswith("docs/"):
                    if text[max(0, m.start() - 5):m.start()].endswith("docs/"):
                        continue
                    problems.append(f"{loc}: '{m.group(0)}' — cite the page by its path, '{DOC_NAME}'")
                    continue
                tail = re.sub(r"\s+", " ", text[m.end():m.end() + 300])
                secs, nts, anchor, eqs, bad, end = _parse_citation(tail)
                cited = (DOC_NAME + tail[:max(end, 20) if bad else end]).rstrip()
                for why in bad:
                    problems.append(f"{loc}: '{cited}' — {why}")
                for s in secs:
                    if s not in sections:
                        problems.append(f"{loc}: '{cited}' cites §{s}, but {DOC_NAME} has sections {have}")
                for k in nts:
                    if k not in notes:
                        problems.append(f"{loc}: '{cited}' cites note {k}, but {DOC_NAME}'s "
                                        f"'{NOTES_HEADING}' has items 1–{max(notes, default=0)}")
                if anchor is not None and anchor not in anchors:
                    problems.append(f"{loc}: '{cited}' links to #{anchor}, which is no heading of {DOC_NAME}")
                for eq in eqs:
                    name = f"({eq[0]}.{eq[1]})"
                    if eq not in tags:
                        problems.append(f"{loc}: '{cited}' cites eq. {name}, which {DOC_NAME} does not tag "
                                        f"(§{eq[0]} has {sum(1 for t in tags if t[0] == eq[0])} equations)")
                    elif secs and eq[0] not in secs:
                        problems.append(f"{loc}: '{cited}' cites eq. {name} next to "
                                        f"{', '.join('§' + str(s) for s in secs)}: the equation is in §{eq[0]}")
    return problems


def test_citations_of_docs_maths_resolve(doc):
    """Every 'docs/maths.md §N', 'note N', '#anchor' and 'eq. (N.M)' names something that exists."""
    problems = _citation_problems(doc)
    if problems:
        pytest.fail(f"{len(problems)} citation(s) of {DOC_NAME} do not resolve (file:line: the citation — why):\n  "
                    + "\n  ".join(problems), pytrace=False)


# --------------------------------------------------------------------------------------------
# no external specification
# --------------------------------------------------------------------------------------------


def _public_files():
    """Every text file under the code directories, the README and the notebooks."""
    files = []
    for d in CODE_DIRS:
        files += sorted(p for p in (ROOT / d).rglob("*") if p.is_file() and p.suffix in TEXT_SUFFIXES
                        and "__pycache__" not in p.parts and ".ipynb_checkpoints" not in p.parts)
    files += [ROOT / "README.md"]
    files += sorted((ROOT / "notebooks").glob("*.ipynb"))
    return [p for p in files if p.is_file()]


def _mentions(pattern: re.Pattern) -> list[str]:
    found = []
    for path in _public_files():
        for where, text in _blobs(path):
            for m in pattern.finditer(text):
                line_start = text.rfind("\n", 0, m.start()) + 1
                line_end = text.find("\n", m.end())
                line = text[line_start:line_end if line_end >= 0 else len(text)].strip()
                found.append(f"{where(m.start())}: {line[:140]}")
    return found


def test_no_reference_to_the_external_specification():
    """No code, README or notebook points at '../shared/docs' (not part of the repository)."""
    found = _mentions(re.compile(r"shared/docs"))
    if found:
        pytest.fail(f"{len(found)} mention(s) of 'shared/docs' — a directory outside the repository that users do "
                    f"not have; cite {DOC_NAME} instead:\n  " + "\n  ".join(found), pytrace=False)


def test_no_stale_MATH_md_citations():
    """No code, README or notebook cites 'MATH.md' (the external specification): cite docs/maths.md."""
    found = _mentions(re.compile(r"MATH\.md"))
    if found:
        pytest.fail(f"{len(found)} citation(s) of 'MATH.md', which is not in the repository; retarget them to "
                    f"'{DOC_NAME} §N' (same section numbers; 'erratum N' → '{DOC_NAME} note N'):\n  "
                    + "\n  ".join(found), pytrace=False)
