// The map-guided identity's gate and module-check thresholds (docs/design/map_identity.md), apart
// from map_identity.hpp so that VisionConfig can hold them (configuration keys vision.identity.*)
// without the identity's code. Pure data.
#pragma once

namespace agv::vision {

struct MapIdentityConfig {
  // Gate: squared Mahalanobis distance (3 dof: x, y, heading) of the innovation between the
  // predicted and the measured landmark-in-vehicle pose. chi2_3dof_quantile(0.999) = 16.27: a
  // correct fix with a consistent covariance is refused once in a thousand frames (it then stays
  // kQrUnreadable, which costs one fix, never a wrong one).
  double gate_chi2 = 16.27;
  // The runner-up must lie beyond this distance: chi2(3) exceeds 60 with probability ~1e-12, so a
  // candidate that far out is not the landmark in view unless the covariance is wrong by a
  // factor of ~2 in sigma (60 / 16.27 = 3.7 in variance). Between the two thresholds the
  // decision is "two plausible" and refused.
  double clear_chi2 = 60.0;
  // Module check (docs/design/map_identity.md "Check 2"), over the visible data modules that are
  // not flat (binarize_samples leaves a patch's inside out). The candidate's code must agree with
  // the sampled bits on at least min_agreement of them: measured >= 0.82 for the right code with a
  // third of the code covered. Alone this does not separate neighbours: their payloads share most
  // characters, so with the same mask their codes share most modules (a wrong neighbour measured
  // up to 0.84). It rejects a landmark that is not in the map, a wrong turn or a wrong version.
  double min_agreement = 0.70;
  // For every other mapped landmark (same code version), on the visible modules where its code
  // and the candidate's differ, the sampled bits must side with the candidate on at least this
  // fraction. Measured (eval_identity, 1/3 covered, realistic imaging): right candidate >= 0.67
  // (the cover can hide most of the modules that tell two similar codes apart; its edge modules
  // are coin flips), wrong candidate <= 0.22. 0.55 leaves about twice the margin to the wrong side.
  double min_pair_agreement = 0.55;
  // At least this many visible differing modules for a pairwise verdict; fewer and the pair
  // cannot be told apart, so the identity is refused (never seen: two payloads differing in the
  // id alone differ on ~100 modules).
  int min_pair_modules = 24;
  // The module check compares the candidate's code with those of this many mapped landmarks
  // nearest to it (docs/design/large_maps.md): the wrong landmark a misplaced prediction lets
  // through the gate is a neighbour (a grid spacing away), and a bounded count keeps the check's
  // cost and the codes it encodes independent of the map's size. 24 covers every other landmark of
  // the maps up to 25 landmarks (the demo's) and, on a 1 m grid, every landmark within 2.5 m.
  int pair_neighbours = 24;
};

}  // namespace agv::vision
