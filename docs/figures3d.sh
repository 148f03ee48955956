#!/bin/sh
# Pictures of the 3D scenes in docs/img (run from the repository root; ~1 minute).
set -e
pointplan render --env boxes3d --robot sshape --seed 1 --observation global -o docs/img/scene_boxes3d.png
pointplan render --env synthetic3d --robot sphere3d --seed 2 --observation local -o docs/img/scene_synthetic3d.png
pointplan render --env ycb3d --robot sshape --seed 0 --observation global -o docs/img/scene_ycb3d.png
pointplan render --env dynamic3d --robot sphere3d --seed 4 --observation local -o docs/img/scene_dynamic3d.png --gif docs/img/rollout_dynamic3d.gif
pointplan render --env slotmoving --robot sshape --seed 5 --observation global -o docs/img/scene_slot.png
pointplan render --env qureshi3d --robot sshape --seed 0 --observation local -o docs/img/scene_qureshi3d.png
