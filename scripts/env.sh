# Sourced by the scripts: puts the tools installed by install-deps.sh on PATH
# (cargo, and vng from the Python that pip installed it into).
export PATH="$HOME/.cargo/bin:$PATH"
py_bin=$(dirname "$(${PYTHON:-python3} -c 'import sys; print(sys.executable)')")
export PATH="$py_bin:$PATH"
unset py_bin
