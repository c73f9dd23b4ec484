"""MkDocs hook: links from a page to repository files outside ``docs/`` point at the repository's web view.

A page may link any file of the repository by its relative path, as the repository's web view resolves it
(``[ppo.yml](../agents/hyperparams/ppo.yml)`` from ``docs/agents.md``). The site holds only ``docs/``, so such a
link is rewritten to ``{repo_url}/blob/{branch}/agents/hyperparams/ppo.yml`` (a folder: ``tree/``; an image:
``raw/``), with ``branch`` from ``extra.source_branch`` in ``mkdocs.yml`` (default ``main``). A target that
does not exist in the repository is left as it is, so that the strict build still reports it as broken.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any
from urllib.parse import unquote

#: An inline link or image: ``[text](target "title")``; the text may span lines.
_INLINE = re.compile(r"(?P<bang>!?)\[(?P<text>[^\]]*)\]\((?P<target>[^)\s]+)(?P<title>\s+\"[^\"]*\")?\)")
#: A reference definition: ``[label]: target``.
_REFERENCE = re.compile(r"^(?P<lead> {0,3}\[[^\]]+\]:\s*)(?P<target>\S+)", re.MULTILINE)
_FENCE = re.compile(r"^\s*(```|~~~)")
_IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".gif", ".svg", ".webp"}


def _repository_url(target: str, page_src: str, docs_dir: Path, root: Path, web: tuple[str, str],
                    image: bool) -> str | None:
    """The web-view URL of ``target`` (relative to the page) if it is a repository file outside docs/."""
    if "://" in target or target.startswith(("#", "/", "mailto:")):
        return None
    path, _, fragment = target.partition("#")
    if not path:
        return None
    resolved = (docs_dir / Path(page_src).parent / unquote(path)).resolve()
    if resolved.is_relative_to(docs_dir) or not resolved.is_relative_to(root) or not resolved.exists():
        return None
    kind = "tree" if resolved.is_dir() else "raw" if image or resolved.suffix.lower() in _IMAGE_SUFFIXES else "blob"
    repo_url, branch = web
    url = f"{repo_url}/{kind}/{branch}/{resolved.relative_to(root).as_posix()}"
    return f"{url}#{fragment}" if fragment else url


def rewrite_links(markdown: str, page_src: str, docs_dir: Path, root: Path, web: tuple[str, str]) -> str:
    """``markdown`` with its links to repository files outside ``docs_dir`` made absolute (code blocks untouched).

    Args:
        markdown: The page's Markdown.
        page_src: The page's path inside ``docs_dir``.
        docs_dir: The documentation folder.
        root: The repository's root folder.
        web: The repository's web URL and the branch to link into.
    """

    def inline(match: re.Match) -> str:
        url = _repository_url(match["target"], page_src, docs_dir, root, web, bool(match["bang"]))
        if url is None:
            return match[0]
        return f"{match['bang']}[{match['text']}]({url}{match['title'] or ''})"

    def reference(match: re.Match) -> str:
        url = _repository_url(match["target"], page_src, docs_dir, root, web, False)
        return match[0] if url is None else f"{match['lead']}{url}"

    out, chunk, fenced = [], [], False
    for line in markdown.splitlines(keepends=True):
        if _FENCE.match(line):
            if not fenced:
                out.append(_REFERENCE.sub(reference, _INLINE.sub(inline, "".join(chunk))))
                chunk = []
            fenced = not fenced
            out.append(line)
        elif fenced:
            out.append(line)
        else:
            chunk.append(line)
    out.append(_REFERENCE.sub(reference, _INLINE.sub(inline, "".join(chunk))))
    return "".join(out)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """MkDocs event: rewrite the page's links before MkDocs validates them."""
    if not config.repo_url:
        return markdown
    web = (config.repo_url.rstrip("/"), (config.extra or {}).get("source_branch", "main"))
    root = Path(config.config_file_path).resolve().parent
    return rewrite_links(markdown, page.file.src_uri, Path(config.docs_dir).resolve(), root, web)
