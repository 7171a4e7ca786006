"""The type stubs cannot drift from the extension (a stubtest in miniature, without mypy).

Every public name of ``_mtpcr.pyi`` exists in ``mtpcr._mtpcr`` and vice versa, class by class;
functions take the parameters the stub says; the keyword arguments of ``Config`` and
``register`` in the stub are exactly the fields of the Rust ``Config``. When a field is added
to the Rust ``Config`` it works at once from Python, and this test asks for its line in the stub.
"""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import mtpcr
from mtpcr import _mtpcr

STUB = Path(mtpcr.__file__).with_name("_mtpcr.pyi")
SOURCE_STUB = Path(__file__).resolve().parents[1] / "mtpcr" / "_mtpcr.pyi"


def public(name: str) -> bool:
    return not name.startswith("_") or name == "__version__"


def names_in(body: list[ast.stmt]) -> dict[str, ast.AST]:
    """Public names bound by a stub body (classes, functions, annotated and plain assignments)."""
    found: dict[str, ast.AST] = {}
    for node in body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            found[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            found[node.target.id] = node
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    found[target.id] = node
    return {k: v for k, v in found.items() if public(k)}


@pytest.fixture(scope="module")
def stub() -> dict[str, ast.AST]:
    assert STUB.is_file(), f"the installed package has no stub at {STUB}"
    if SOURCE_STUB.is_file():
        assert STUB.read_text() == SOURCE_STUB.read_text(), (
            "the installed stub differs from python/mtpcr/_mtpcr.pyi: reinstall the package"
        )
    return names_in(ast.parse(STUB.read_text()).body)


def config_fields() -> set[str]:
    return set(mtpcr.Config().to_dict())


def stub_params(node: ast.FunctionDef) -> tuple[list[str], list[str]]:
    args = node.args
    positional = [a.arg for a in args.posonlyargs + args.args if a.arg != "self"]
    return positional, [a.arg for a in args.kwonlyargs]


def test_module_names_match(stub):
    runtime = {n for n in dir(_mtpcr) if public(n)}
    assert sorted(set(stub) - runtime) == [], "in the stub but not in the module"
    assert sorted(runtime - set(stub)) == [], "in the module but not in the stub"
    assert sorted(mtpcr.__all__) == sorted(runtime), "mtpcr.__all__ re-exports the module"


@pytest.mark.parametrize("class_name", ["Config", "Registration", "Problem"])
def test_class_members_match(stub, class_name):
    node = stub[class_name]
    assert isinstance(node, ast.ClassDef)
    in_stub = set(names_in(node.body))
    cls = getattr(_mtpcr, class_name)
    # Config's fields are served by __getattr__ and listed by __dir__ on instances.
    where = cls() if class_name == "Config" else cls
    runtime = {n for n in dir(where) if not n.startswith("_")}
    missing = sorted(in_stub - runtime)
    extra = sorted(runtime - in_stub)
    assert missing == [], f"{class_name}: in the stub but not at runtime: {missing}"
    assert extra == [], (
        f"{class_name}: at runtime but not in python/mtpcr/_mtpcr.pyi: {extra} "
        "(a new Config field needs a property, and a keyword in Config.__init__ and register)"
    )


def test_config_and_register_keywords_are_the_config_fields(stub):
    fields = config_fields()
    init = next(
        n for n in stub["Config"].body if isinstance(n, ast.FunctionDef) and n.name == "__init__"
    )
    positional, keywords = stub_params(init)
    assert positional == []
    assert sorted(set(keywords) ^ fields) == [], "Config.__init__ keywords vs Config fields"
    positional, keywords = stub_params(stub["register"])
    assert positional == [] and stub["register"].args.vararg.arg == "clouds"
    expected = (fields - {"seed"}) | {
        "seed",
        "on_generation",
        "on_pair_screening",
        "config",
        "viewpoints",
        "screening",
    }
    assert sorted(set(keywords) ^ expected) == [], "register keywords vs Config fields"
    assert len(keywords) == len(set(keywords))
    positional, keywords = stub_params(stub["screen_pairs"])
    assert positional == [] and stub["screen_pairs"].args.vararg.arg == "clouds"
    expected = (expected - {"on_generation", "screening"}) | {"pairs"}
    assert sorted(set(keywords) ^ expected) == [], "screen_pairs keywords vs Config fields"


def test_config_property_docs_are_the_rust_field_docs(stub):
    """The stub documents each field with the text of the Rust doc comment (the same text as
    the CLI help), so the three cannot drift."""
    docs = mtpcr.Config.field_docs()
    props = {
        n.name: " ".join((ast.get_docstring(n) or "").split())
        for n in stub["Config"].body
        if isinstance(n, ast.FunctionDef) and n.name in docs
    }
    assert sorted(props) == sorted(docs)
    for name, text in docs.items():
        assert props[name] == text, f"Config.{name}: the stub's docstring differs from Rust's"


@pytest.mark.parametrize(
    "name",
    [
        "register",
        "read_ply",
        "read_points",
        "read_scans",
        "write_ply",
        "load_problem",
        "evaluate",
        "evaluate_pairs",
        "find_shared_dir",
    ],
)
def test_function_signatures_match(stub, name):
    runtime = inspect.signature(getattr(_mtpcr, name))
    kinds = inspect.Parameter
    run_pos = [
        p.name
        for p in runtime.parameters.values()
        if p.kind in (kinds.POSITIONAL_ONLY, kinds.POSITIONAL_OR_KEYWORD)
    ]
    run_kw = [p.name for p in runtime.parameters.values() if p.kind == kinds.KEYWORD_ONLY]
    positional, keywords = stub_params(stub[name])
    assert positional == run_pos
    # register also takes **settings, which the stub spells out field by field.
    assert keywords[: len(run_kw)] == run_kw
    if not any(p.kind == kinds.VAR_KEYWORD for p in runtime.parameters.values()):
        assert keywords == run_kw


def test_the_stub_is_shipped_with_py_typed():
    assert STUB.with_name("py.typed").is_file()
