"""Every code example of the site's pages runs, and prints what the page shows."""

from pathlib import Path

import pytest

from .doc_examples import examples, outputs_match, run_page

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted(p for p in (ROOT / "docs").glob("*.md"))
WITH_EXAMPLES = [p for p in PAGES if examples(p.read_text())]


def check_page(path: Path, folder: Path) -> None:
    """Run ``path``'s examples; fail on an error, an output not shown or not as shown."""
    page = examples(path.read_text())
    printed = run_page(page, folder)
    for example, result in zip(page, printed, strict=False):
        where = f"{path.name}, the example at line {example.line}"
        assert result["error"] is None, f"{where} raised:\n{result['error']}"
        if example.shown is None:
            assert not result["out"].strip(), f"{where} prints but shows no output:\n" \
                                              f"{result['out']}"
        else:
            assert outputs_match(example.shown, result["out"]), (
                f"{where} shows\n{example.shown}\nbut printed\n{result['out']}")
    assert len(printed) == len(page)


def test_the_pages_have_examples():
    assert len(WITH_EXAMPLES) >= 8, [p.name for p in WITH_EXAMPLES]


@pytest.mark.parametrize("path", WITH_EXAMPLES, ids=lambda p: p.name)
def test_page_examples_print_what_they_show(path, tmp_path):
    check_page(path, tmp_path)


# the checker itself: it must refuse what differs, not only accept what matches
@pytest.mark.parametrize(("shown", "printed", "same"), [
    ("error 2.5e-16", "error 2.5e-16", True),
    ("error 2.5e-16", "error 2.6e-16", True),  # one unit of the last digit written
    ("error 2.5e-16", "error 2.8e-16", False),
    ("max error 0.0032", "max error 0.00321", True),
    ("max error 0.0032", "max error 0.0045", False),
    ("True 12 0", "True 12 0", True),
    ("True 12 0", "False 12 0", False),
    ("ur5: 6 joints", "ur5: 6 joints", True),
    ("ur5: 6 joints", "ur3: 6 joints", False),
    ("frames: ['a', ...]", "frames: ['a', 'b', 'c']", True),
    ("line one\nline two", "line one\nline two\n\n", True),
    ("line one\nline two", "line one", False),
    ("closest 10.0 mm", "closest 9.2 mm", False),
])
def test_the_output_checker(shown, printed, same):
    assert outputs_match(shown, printed) is same


def test_an_output_block_belongs_to_the_block_just_before_it():
    text = ("```python\nprint(1)\n```\n\n```text\n1\n```\n\nprose\n\n```python\nx = 2\n```\n\n"
            "words\n\n```text\nnot its output\n```\n")
    first, second = examples(text)
    assert first.shown == "1\n" and first.line == 2
    assert second.shown is None
