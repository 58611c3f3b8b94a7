"""config.yaml's comments say what a key means in one line; why a knob has its value (the val study that chose it and
its numbers) lives in docs/decisions/<stage>.md, one heading per knob, which the key's comment links to."""
import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "config.yaml"
LINK = re.compile(r"docs/decisions/([a-z_]+\.md)#([A-Za-z0-9_.]+)")


def comments(text: str) -> list[str]:
    """Every YAML comment of ``text``, '#' to the end of the line: a '#' at a line start or after a blank, outside
    every scalar (quoted strings and block scalars hold '#' that are text)."""
    scalars = sorted((t.start_mark.index, t.end_mark.index) for t in yaml.scan(text, Loader=yaml.SafeLoader)
                     if isinstance(t, yaml.ScalarToken))
    out, i, k = [], 0, 0
    while i < len(text):
        while k < len(scalars) and scalars[k][1] <= i:
            k += 1
        if k < len(scalars) and scalars[k][0] <= i:
            i = scalars[k][1]
        elif text[i] == "#" and (i == 0 or text[i - 1] in " \t\n"):
            end = text.find("\n", i)
            end = len(text) if end < 0 else end
            out.append(text[i:end])
            i = end
        else:
            i += 1
    return out


def test_comments_are_found_outside_strings_only():
    text = 'a: 1  # one\nb: "x # not a comment"\nc: >-\n  # text of c\n  more\n# two\nd: [1, 2]  # three\n'
    assert comments(text) == ["# one", "# two", "# three"]


def test_comments_are_at_most_a_quarter_of_the_config():
    text = CONFIG.read_text()
    share = sum(map(len, comments(text))) / len(text)
    assert share <= 0.25, f"comments are {share:.1%} of config.yaml's characters: move the rationale to docs/decisions/"


def test_no_changelog_in_comments():
    for c in comments(CONFIG.read_text()):
        assert not re.search(r"\b20\d\d-\d\d\b", c), f"a date: {c}"
        assert not re.search(r"\bissue\b|#\d", c, re.I), f"an issue number: {c}"
        assert not re.search(r"\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b", c), f"a commit: {c}"
        assert not re.search(r"\bBefore\b|\buntil\b", c), f"a changelog: {c}"


def test_decision_links_resolve():
    links = LINK.findall(CONFIG.read_text())
    assert len(links) >= 30
    for page, anchor in links:
        doc = ROOT / "docs" / "decisions" / page
        assert doc.is_file(), page
        assert f'<a id="{anchor}"></a>' in doc.read_text(), f"{page} has no heading for {anchor}"


def test_decisions_name_studies_that_exist():
    for doc in sorted((ROOT / "docs" / "decisions").glob("*.md")):
        for script in re.findall(r"studies/[a-z_0-9]+\.(?:py|yaml)", doc.read_text()):
            assert (ROOT / script).is_file(), f"{doc.name}: {script}"


def test_config_names_scripts_that_exist():
    """A caption note or comment of config.yaml that cites a script (a study, a benchmark) names one the repo has."""
    named = re.findall(r"\b((?:benchmarks|studies|tools|drills)/[a-z_0-9]+\.py)\b", CONFIG.read_text())
    assert named, "config.yaml cites no script any more: drop this test"
    missing = sorted({s for s in named if not (ROOT / s).is_file()})
    assert not missing, missing
