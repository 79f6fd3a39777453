#!/usr/bin/env bash
# Distribution check (`make dist-check`, part of `make test`): what a user of the wheel gets.
#
# 1. build the sdist and, from it, the wheel (`python -m build`, the declared build backend in
#    an isolated environment); `twine check --strict` both;
# 2. the wheel holds every module of the package, the MJCF assets, the fitted values
#    (assets/fits), the shipped policies and their model cards, the licence, and nothing of
#    the repository around the package;
# 3. install the wheel alone (--no-deps) into a fresh venv that sees .venv's site-packages
#    through a .pth line (the dependencies, torch included, are not downloaded again; .pth
#    files of .venv, such as its editable install of myoexo, are not run), and from outside
#    the repository run `myoexo --version`, `myoexo --help`, an env reset and the shipped
#    policies, checking that `myoexo` is imported from the wheel.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PY=${PY:-$ROOT/.venv/bin/python}
start=$(date +%s)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/myoexo-dist.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

echo "dist-check: building sdist and wheel"
"$PY" -m build --outdir "$WORK/dist" . >"$WORK/build.log" 2>&1 || { cat "$WORK/build.log"; exit 1; }
"$PY" -m twine check --strict "$WORK"/dist/*

echo "dist-check: contents"
"$PY" - "$ROOT" "$WORK/dist" <<'EOF'
import sys, tarfile, zipfile
from pathlib import Path

root, dist = Path(sys.argv[1]), Path(sys.argv[2])
(wheel,) = dist.glob("myoexo-*.whl")
(sdist,) = dist.glob("myoexo-*.tar.gz")
names = set(zipfile.ZipFile(wheel).namelist())
package = root / "myoexo"
expected = {
    p.relative_to(root).as_posix()
    for p in package.rglob("*")
    if p.is_file()
    and "__pycache__" not in p.parts
    and (p.suffix == ".py" or p.parent.name in ("assets", "fits", "policies"))
}
missing = sorted(expected - names)
assert not missing, f"the wheel lacks {missing}"
for required in ("myoexo/assets/exo_knee.xml", "myoexo/assets/fits/pid_tuned_exo.json",
                 "myoexo/policies/sac_knee_exo.npz",
                 "myoexo/policies/student_exo.npz", "myoexo/policies/residual_knee_exo.npz",
                 "myoexo/policies/student_fine.npz", "myoexo/policies/MODEL_CARD.md"):
    assert required in names, f"the wheel lacks {required}"
stray = sorted(n for n in names if not n.startswith(("myoexo/", "myoexo-")))
assert not stray, f"the wheel holds files outside the package: {stray}"
info = next(n for n in names if n.endswith(".dist-info/METADATA"))
meta = zipfile.ZipFile(wheel).read(info).decode()
assert "License-Expression: Apache-2.0" in meta, "no SPDX licence expression in METADATA"
assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names), "no LICENSE in the wheel"
sdist_names = tarfile.open(sdist).getnames()
for required in ("LICENSE", "README.md", "pyproject.toml", "myoexo/assets/exo_knee.xml"):
    assert any(n.endswith("/" + required) for n in sdist_names), f"the sdist lacks {required}"
print(f"  {wheel.name}: {len(names)} files; {sdist.name}: {len(sdist_names)} entries")
EOF

echo "dist-check: installing the wheel into a fresh venv"
"$PY" -m venv "$WORK/venv"
site=$("$WORK/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
"$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])' >"$site/_myoexo_deps.pth"
"$WORK/venv/bin/python" -m pip install -q --no-deps --no-index --disable-pip-version-check \
    "$WORK"/dist/myoexo-*.whl

cd /tmp
version=$("$WORK/venv/bin/myoexo" --version)
echo "  $version"
expected="myoexo $("$PY" -c 'import importlib.metadata as m; print(m.version("myoexo"))')"
if [ "$version" != "$expected" ]; then
    echo "dist-check: the wheel's 'myoexo --version' says '$version', expected '$expected'" >&2
    exit 1
fi
"$WORK/venv/bin/myoexo" --help >/dev/null
MYOEXO_WHEEL_SITE=$site "$WORK/venv/bin/python" -c '
import os, gymnasium as gym, myoexo
site = os.path.realpath(os.environ["MYOEXO_WHEEL_SITE"])
assert os.path.realpath(myoexo.__file__).startswith(site + os.sep), myoexo.__file__
env = gym.make("MyoExoKnee-v1")
env.reset(seed=0)
from myoexo.policies import SHIPPED_POLICIES, load_policy
for name in SHIPPED_POLICIES:
    load_policy(name)  # as stored
    myoexo.load_policy(name, env)  # as it runs (a residual policy on its base)
from myoexo.control.tuned import TUNED_PIDS
assert {"exo", "latency"} <= set(TUNED_PIDS), TUNED_PIDS
print("  import, env reset, shipped policies and tuned PIDs from", os.path.dirname(myoexo.__file__))
'
echo "dist-check: passed in $(($(date +%s) - start)) s"
