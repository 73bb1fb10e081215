// Which refinement oracle builds the links (Sec. 3.2), shared by the link builder and the
// solver settings.
#pragma once

namespace penumbra {

enum class LinkOracle {
    // Bounding spheres of both ends against oracle × ω_bin (the receiver's against
    // oracle × receiverOracle × ω_bin), overlapping pairs refined (default; most accurate).
    kConservative,
    // Sec. 3.2 as written: the sender's area-based solid angle only (fewest links).
    kPaper,
    // The paper's area-based solid angle for the sender, and for the receiver against
    // oracle × receiverOracle × ω_bin: a large receiver would hand one direction and one
    // distance to all its members. Fewer links than the conservative oracle, and a better
    // answer than the paper's at the same count (docs/ACCURACY.md, office).
    kArea,
};

}  // namespace penumbra
