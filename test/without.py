"""A child process without some Python packages: ``env_without(tmp_path, "daqp")`` is an environment whose
Python cannot import ``daqp`` (a ``sitecustomize`` on PYTHONPATH sets ``sys.modules["daqp"] = None``, so
``import daqp`` raises ImportError as it does where the package is not installed), the rest of the venv as it is.
The children of that process (sweep workers, nodes) inherit it."""
import os
from pathlib import Path
from typing import Dict

SITECUSTOMIZE = '''import os, sys
for _name in os.environ.get("MWIP_TEST_WITHOUT", "").split(","):
    if _name:
        sys.modules[_name] = None
'''


def env_without(tmp_path: Path, *modules: str, base: Dict[str, str] = None) -> Dict[str, str]:
    """``base`` (default: this process's environment) with ``modules`` made unimportable for Python."""
    shim = Path(tmp_path) / "without_shim"
    shim.mkdir(exist_ok=True)
    (shim / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = dict(os.environ if base is None else base)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(shim), env.get("PYTHONPATH", "")) if p)
    env["MWIP_TEST_WITHOUT"] = ",".join(modules)
    return env
