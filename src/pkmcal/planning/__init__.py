"""Planning: which poses to measure (paper 2 §4, paper 1 §IV).

* :mod:`.indices`    — observability indices O1..O5 of per-pose Jacobian blocks G (N, m, n)
* :mod:`.candidates` — candidate poses (box corners, random, grid, CSV), workspace box,
  reachability and measurability checks with rejection counts
* :mod:`.blocks`     — G from the identification engine (whitened, scaled, identifiable)
* :mod:`.selection`  — default D-optimal exchange, detmax, cuckoo, corners, random
* :mod:`.error_maps` — pose-error maps over workspace slices (paper 1 Figs 4–9)
* :mod:`.plan`       — end to end: :func:`~.plan.plan_poses`, :func:`~.plan.pose_set_indices`
"""
