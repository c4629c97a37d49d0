#!/bin/sh
# The pictures of docs/guide.md's "Pictures" section, made by exactly the commands it shows.
# Run from the repository root: sh docs/img/make_images.sh (needs the package installed).
set -e
cd "$(dirname "$0")"
trap 'rm -f aligned.npz grid.npy' EXIT
anisosample points aligned -n 256 --directions 0,90,30 --seed 0 -o aligned.npz
python - <<'PY'
import jax.numpy as jnp
import numpy as np
from anisosample import integrands

f = integrands.edges([30.0, 75.0, 150.0])       # edges with spectral directions 30, 75, 150
s = 576                                          # 6 x 6 blocks of 96^2 samples
c = (jnp.arange(s, dtype=jnp.float32) + 0.5) / s
ys, xs = jnp.meshgrid(c, c, indexing="ij")
np.save("grid.npy", np.asarray(f(jnp.stack([xs, ys], axis=-1))))  # values[i, j] = f(x_j, y_i)
PY
anisosample spectrum aligned.npz -o spectrum.png --radius 32 --mark-directions 30 --force
anisosample spectrum aligned.npz -o spectrum_log.png --radius 32 --scale log --clip none --force
anisosample directions grid.npy --block 96 -o directions.png --force
