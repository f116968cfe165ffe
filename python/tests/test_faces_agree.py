"""The package's faces against the library's tables (`_rigidcells.names()`): every option of a
deformation is a keyword of each function that deforms, in the stub as in the package; the stub's
and the Blender add-on's lists of names are the library's, so none can drift by hand."""

import ast
import inspect
import os

import rigidcells
from rigidcells import _rigidcells

HERE = os.path.dirname(os.path.abspath(__file__))
STUB = os.path.join(os.path.dirname(rigidcells.__file__), "__init__.pyi")
ADDON = os.path.join(HERE, "..", "..", "blender", "rigidcells_blender", "__init__.py")

# The functions and methods that take a deformation's options, by their stub names.
DEFORMING = ["deform", "solve", "estimate", "deform_file", "Session.__init__"]


def stub():
    with open(STUB, encoding="utf-8") as f:
        return ast.parse(f.read())


def literal_names(node, aliases):
    """The names a `Literal[...]` annotation (inside `Optional[...]`, or through an alias)
    allows, or None."""
    if isinstance(node, ast.Name) and node.id in aliases:
        return aliases[node.id]
    if isinstance(node, ast.Subscript):
        base = node.value.id if isinstance(node.value, ast.Name) else None
        if base == "Literal":
            items = node.slice.elts if isinstance(node.slice, ast.Tuple) else [node.slice]
            return [i.value for i in items]
        if base == "Optional":
            return literal_names(node.slice, aliases)
    return None


def stub_functions(tree):
    """Stub name -> list of its definitions (overloads give several)."""
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            out.setdefault(node.name, []).append(node)
        if isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    out.setdefault(f"{node.name}.{item.name}", []).append(item)
    return out


def aliases_of(tree):
    out = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
            names = literal_names(node.value, {})
            if names is not None:
                out[node.targets[0].id] = names
    return out


def test_every_option_is_a_keyword_of_every_deforming_function():
    keywords, _ = _rigidcells.names()
    functions = stub_functions(stub())
    for name in DEFORMING:
        assert name in functions, f"{name} is not in the stub"
        for definition in functions[name]:
            args = {a.arg for a in definition.args.kwonlyargs + definition.args.args}
            missing = [k for k in keywords if k not in args]
            assert not missing, f"the stub's {name} lacks {missing}"
        # The package itself takes them too.
        owner, _, attr = name.partition(".")
        function = getattr(getattr(rigidcells, owner), attr) if attr else getattr(rigidcells, owner)
        parameters = inspect.signature(function).parameters
        takes_any = any(p.kind == p.VAR_KEYWORD for p in parameters.values())
        missing = [k for k in keywords if k not in parameters]
        assert takes_any or not missing, f"rigidcells.{name} lacks {missing}"


def test_the_stubs_names_are_the_librarys():
    _, choices = _rigidcells.names()
    tree = stub()
    aliases = aliases_of(tree)
    # The same names; the order is each face's own (a face lists its default first).
    assert sorted(aliases["Transfer"]) == sorted(choices["transfer"])
    assert sorted(aliases["Outside"]) == sorted(choices["outside"])
    checked = set()
    for definitions in stub_functions(tree).values():
        for definition in definitions:
            for a in definition.args.kwonlyargs + definition.args.args:
                if a.arg in choices and a.annotation is not None:
                    names = literal_names(a.annotation, aliases)
                    if names is not None:
                        assert sorted(names) == sorted(choices[a.arg]), (definition.name, a.arg)
                        checked.add(a.arg)
    assert checked == set(choices), checked


def test_blenders_transfers_are_the_librarys():
    _, choices = _rigidcells.names()
    with open(ADDON, encoding="utf-8") as f:
        tree = ast.parse(f.read())
    lists = {
        node.targets[0].id: ast.literal_eval(node.value)
        for node in tree.body
        if isinstance(node, ast.Assign)
        and isinstance(node.targets[0], ast.Name)
        and node.targets[0].id == "TRANSFERS"
    }
    assert sorted(item[0] for item in lists["TRANSFERS"]) == sorted(choices["transfer"])
