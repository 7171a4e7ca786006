#!/usr/bin/env python3
"""Rewrites the Config part of python/mtpcr/_mtpcr.pyi from the installed extension: one
property per field with the Rust doc comment as its docstring, and the keyword arguments of
``Config.__init__``, ``register`` and ``screen_pairs``. Run after adding a setting
(``pip install .`` first); ``python/tests/test_stubs.py`` checks the result.
"""

import re
import textwrap
from pathlib import Path

import mtpcr

STUB = Path(__file__).resolve().parents[1] / "python" / "mtpcr" / "_mtpcr.pyi"
# Python types of the settings: by the Rust field's kind, else named here.
TYPES = {
    "order": "_Order",
    "method": "_Method",
    "sampling": "_Sampling",
    "search": "_Search",
    "seed": "int | None",
}


def python_type(name: str, value: object) -> str:
    if name in TYPES:
        return TYPES[name]
    return type(value).__name__


def main() -> None:
    docs = mtpcr.Config.field_docs()
    defaults = mtpcr.Config().to_dict()
    types = {name: python_type(name, defaults[name]) for name in docs}
    props = []
    for name, doc in docs.items():
        props.append("    @property")
        props.append(f"    def {name}(self) -> {types[name]}:")
        lines = textwrap.wrap(
            doc,
            88,
            initial_indent='        """',
            subsequent_indent="        ",
            break_on_hyphens=False,
        )
        lines[-1] += '"""'
        props += lines
    text = STUB.read_text()
    start = text.index("    @property\n    def ", text.index("class Config:"))
    end = text.index("class Registration:")
    text = text[:start] + "\n".join(props) + "\n\n" + text[end:]
    init = "".join(f"        {n}: {types[n]} = ...,\n" for n in docs)
    text = re.sub(
        r"(    def __init__\(\n        self,\n        \*,\n)(.*?)(    \) -> None: \.\.\.)",
        lambda m: m.group(1) + init + m.group(3),
        text,
        flags=re.S,
    )
    kwargs = "".join(f"    {n}: {types[n]} = ...,\n" for n in docs if n != "seed")
    # The settings of `register` and `screen_pairs`: their last keywords, from the first
    # Config field up to the return type (the keywords before it stay as written).
    first = next(iter(docs))
    for function, returns in (("register", "Registration"), ("screen_pairs", "dict")):
        text = re.sub(
            rf"(def {function}\(\n.*?\n)(    {first}: .*?)(\) -> {returns})",
            lambda m: m.group(1) + kwargs + m.group(3),
            text,
            flags=re.S,
        )
    STUB.write_text(text)
    print(f"rewrote the Config part of {STUB}")


if __name__ == "__main__":
    main()
