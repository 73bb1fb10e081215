"""Builds penumbra_client with its protocol code generated from protocol/penumbra.fbs.

`flatc --python` writes the payload tables as the package `penumbra.protocol.fb`; they are
placed in `penumbra_client/_fb` with their imports pointed there, so nothing named `penumbra`
lands in site-packages. Needs flatc (Debian: flatbuffers-compiler) at build time.
"""
import os
import pathlib
import shutil
import subprocess
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = pathlib.Path(__file__).resolve().parent
SCHEMA = HERE.parent.parent / "protocol" / "penumbra.fbs"


class BuildWithGeneratedProtocol(build_py):
    def run(self):
        super().run()
        schema = pathlib.Path(os.environ.get("PENUMBRA_FBS", SCHEMA))
        if not schema.is_file():
            raise SystemExit(f"penumbra_client: {schema} not found (set PENUMBRA_FBS)")
        flatc = shutil.which("flatc")
        if not flatc:
            raise SystemExit("penumbra_client: flatc not found (Debian: flatbuffers-compiler)")
        target = pathlib.Path(self.build_lib) / "penumbra_client" / "_fb"
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run([flatc, "--python", "-o", tmp, str(schema)], check=True)
            generated = pathlib.Path(tmp) / "penumbra" / "protocol" / "fb"
            shutil.rmtree(target, ignore_errors=True)
            target.mkdir(parents=True)
            for source in generated.glob("*.py"):
                text = source.read_text().replace(
                    "from penumbra.protocol.fb.", "from penumbra_client._fb.")
                (target / source.name).write_text(text)


setup(cmdclass={"build_py": BuildWithGeneratedProtocol})
