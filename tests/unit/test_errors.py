"""Each package keeps its error classes in its errors.py, under one base class; the software
version is written in one place per package."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {'sessgan_core': 'SessganCoreError', 'sessgan_gen': 'SessganGenError',
            'sessgan_sim': 'SessganSimError',
            'sessgan_evolver': 'SessganEvolverError',
            'sessgan_controllers': 'SessganControllersError'}
FOLDERS = {'sessgan_core': 'sessgan_core', 'sessgan_gen': 'sessgan_gen',
           'sessgan_sim': 'sessgan_sim',
           'sessgan_evolver': 'sessgan_evolver', 'sessgan_controllers': 'controllers'}


def exception_classes_outside_errors_py() -> list[str]:
    found = []
    for package, folder in FOLDERS.items():
        for path in (ROOT / folder / package).glob('*.py'):
            if path.name == 'errors.py':
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ClassDef) and any(
                        getattr(base, 'id', '').endswith(('Error', 'Exception'))
                        for base in node.bases):
                    found.append(f'{package}/{path.name}: {node.name}')
    return found


def test_error_classes_live_in_errors_py():
    assert exception_classes_outside_errors_py() == []


@pytest.mark.parametrize('package', sorted(PACKAGES))
def test_every_error_derives_from_the_package_base(package):
    errors = importlib.import_module(f'{package}.errors')
    base = getattr(errors, PACKAGES[package])
    classes = [value for value in vars(errors).values()
               if isinstance(value, type) and issubclass(value, Exception)
               and value.__module__ == errors.__name__]
    assert len(classes) > 1
    assert all(issubclass(cls, base) for cls in classes)


def test_the_version_string_is_not_repeated_in_the_code():
    literal = re.compile(r"""['"]\d+\.\d+\.\d+['"]""")
    found = [f'{path.relative_to(ROOT)}:{number}'
             for folder in FOLDERS.values() for path in (ROOT / folder).rglob('*.py')
             if path.name not in ('setup.py', '__init__.py')
             for number, line in enumerate(path.read_text().splitlines(), 1)
             if literal.search(line) and 'version' in line.lower()]
    assert found == []
