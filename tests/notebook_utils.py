"""Running a notebook headless in a test and reading its outputs (shared by tests/test_notebook_*.py)."""

from __future__ import annotations

from pathlib import Path

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


def cell_text(cell, html_chars: int = 0) -> str:
    """A code cell's printed text and plain-text results, ``<png>`` for each image, and optionally the
    first ``html_chars`` characters of each HTML result."""
    out: list[str] = []
    prev_stream, at = None, -1
    for o in cell.get("outputs", []):
        data = o.get("data", {})
        if o.get("output_type") == "stream" and o.get("name") == prev_stream:
            # one print may reach the kernel's output thread in pieces on a loaded machine: join them as
            # Jupyter shows them, not with the line breaks that separate outputs
            out[at] += o.get("text", "")
            continue
        prev_stream = o.get("name") if o.get("output_type") == "stream" else None
        at = len(out)
        out.append(o.get("text", ""))
        out.append(str(data.get("text/plain", "")))
        if html_chars:
            out.append(str(data.get("text/html", ""))[:html_chars])
        if "image/png" in data:
            out.append("<png>")
    return "\n".join(out)


def execute(name: str, workdir: Path, timeout: int = 300, html_chars: int = 0):
    """Execute ``notebooks/<name>`` in ``workdir``; returns (notebook, texts of its code cells)."""
    import nbclient
    import nbformat

    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(workdir)}}).execute()
    return nb, [cell_text(c, html_chars) for c in nb.cells if c.cell_type == "code"]
