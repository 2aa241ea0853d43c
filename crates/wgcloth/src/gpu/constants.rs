//! Constants the host and the kernels share, written here once: every
//! stage is compiled with [`prelude`] in front of it, and no WGSL file
//! declares one of these itself (a test checks both directions).

use crate::cpu::{contact, impact, separate};
use crate::health;
use crate::multigrid;
pub use crate::nn::weights::{CONTACT_FRAME_ROWS, WORLD_FRAME_ROWS};

/// Invocations per workgroup of the per-element kernels.
pub const WORKGROUP: u32 = 256;
/// "No triangle here" in a triangle index.
pub const NO_TRIANGLE: u32 = u32::MAX;
/// Cloth grid cells per tile edge, and tiles per super-tile edge (the
/// face–vertex broad phase).
pub const TILE: u32 = 8;
/// Lanes of a face–vertex workgroup: one per cell of a tile.
pub const FACE_VERTEX_LANES: u32 = TILE * TILE;

/// Invocations per workgroup of the network batch's kernels (`batch::plan`,
/// `mlp::per_contact`).
pub const BATCH_GROUP: u32 = 64;

/// Stage "separate"'s buffer (wgsl/separate.wgsl): sections of words per
/// cloth vertex, each n times its words long and in this order (the
/// section's start is its constant times n), then the header.
pub mod separations {
    /// The least separation of the vertex's near pairs, as f32 bits.
    pub const LEAST: u32 = 0;
    /// Its flags (the `FLAG_*` bits below).
    pub const FLAGS: u32 = 1;
    /// Failing pairs at the vertex in an impulse round; the zone's free
    /// vertices in a zone round.
    pub const COUNT: u32 = 2;
    /// Its impact zone's label.
    pub const LABEL: u32 = 3;
    /// The label a zone round's hooks lower.
    pub const NEXT: u32 = 4;
    /// Its zone's lowest vertex the failsafe may not move (u32::MAX: none).
    pub const ANCHOR: u32 = 5;
    /// Its step, three f32s' bits.
    pub const STEP: u32 = 6;
    /// A fixed-point sum of three 64-bit integers, each as its low word
    /// then its high word: a round's impulses, or its zone's steps.
    pub const SUM: u32 = 9;
    /// Its step when the current detection ran, three f32s' bits: what its
    /// boxes and near pairs were found for.
    pub const SWEPT: u32 = 15;
    /// Words per vertex; the header follows them.
    pub const WORDS: u32 = 18;
    /// Flag: held by the last resort.
    pub const HELD: u32 = 1;
    /// Flag: held by the last resort's round just run.
    pub const HELD_NEW: u32 = 2;
    /// Flag: changed by an impulse round.
    pub const PUSHED: u32 = 4;
    /// Flag: in an impact zone.
    pub const ZONED: u32 = 8;
    /// Flag: stopped by the body in the failsafe.
    pub const BODY: u32 = 16;
    /// Marks a zone's anchor word offered by a vertex stopped against the
    /// body, so that any fixed vertex's index (below it) wins.
    pub const ANCHOR_BODY: u32 = 1 << 31;
}

/// Words of stage "separate"'s header (wgsl/separate.wgsl), after its
/// words per vertex, and of its dispatch buffer.
pub mod self_header {
    /// Near pairs the current detection found (listed up to the capacity).
    pub const PAIR_COUNT: u32 = 0;
    /// Pairs the last test found failing.
    pub const FAILING: u32 = 1;
    /// Vertices the last resort's last round held for the first time.
    pub const CHANGED: u32 = 2;
    /// 1 when the last resort's last round held anything new.
    pub const UNSETTLED: u32 = 3;
    /// 1 once a detection found no pair failing, or the last resort ran:
    /// the rest of the step's dispatches are empty.
    pub const SETTLED: u32 = 4;
    /// 1 between a detection and its first test.
    pub const FIRST: u32 = 5;
    /// 1 when the last detection found pairs failing.
    pub const LAST_RESORT: u32 = 6;
    /// Detections run.
    pub const DETECTED: u32 = 7;
    /// The most pairs a detection found.
    pub const MOST_PAIRS: u32 = 8;
    /// The header's length.
    pub const WORDS: u32 = 9;
    /// In the dispatch buffer (a buffer of its own: a dispatch cannot read
    /// its arguments from a buffer it writes), three words each: a
    /// detection's `prepare` (vertices and cells),
    pub const PREPARE_ARGS: u32 = 0;
    /// its tiles,
    pub const TILES_ARGS: u32 = 3;
    /// its super-tiles,
    pub const SUPERTILES_ARGS: u32 = 6;
    /// and its walks;
    pub const WALKS_ARGS: u32 = 9;
    /// a test or push over the listed pairs,
    pub const LIST_ARGS: u32 = 12;
    /// or, when the list overflowed, the walks again in its place;
    pub const RETEST_ARGS: u32 = 15;
    /// a round's pass over the vertices;
    pub const VERTEX_ARGS: u32 = 18;
    /// the last resort's round over the list,
    pub const ROUND_ARGS: u32 = 21;
    /// its settle,
    pub const SETTLE_ARGS: u32 = 24;
    /// and its round's walks when the list overflowed.
    pub const RECHECK_ARGS: u32 = 27;
    /// The dispatch buffer's length.
    pub const DISPATCH_WORDS: u32 = 30;
}

/// Stage "self_contact"'s list buffer (wgsl/self_contact.wgsl): this
/// header, then per vertex its count of contacts found, its count listed,
/// and its list of `Params::cloth_per_vertex` entries (4 · contact + the
/// vertex's slot in it).
pub mod cloth_header {
    /// Contacts found (kept up to `Params::cloth_capacity`).
    pub const COUNT: u32 = 0;
    /// Contacts left out this step.
    pub const DROPPED: u32 = 1;
    /// The header's length.
    pub const WORDS: u32 = 4;
    /// Words per vertex after it besides its list: its two counts.
    pub const COUNTS: u32 = 2;
}

/// `Params::motion_kind`: how the rigid body moves (wgsl/rigid.wgsl).
pub mod motion {
    /// The body stays where it is placed.
    pub const STATIC: u32 = 0;
    /// Constant velocity, `Params::motion_vector`.
    pub const LINEAR: u32 = 1;
    /// A sinusoid along the unit axis `Params::motion_vector`.
    pub const SINUSOID: u32 = 2;
}

/// `Params::model`: which contact model the kernels evaluate.
pub mod model {
    /// `ModelKind::Naive`: the penalty force f = −c d̃ n (thesis eq. 6).
    pub const NAIVE: u32 = 0;
    /// `ModelKind::Friction`: contact and Coulomb friction force (thesis eqs. 8–9).
    pub const FRICTION: u32 = 1;
    /// `ModelKind::FrictionNet`: the friction force from the trained
    /// network (thesis 2.6–2.7).
    pub const FRICTION_NET: u32 = 2;
    /// `ModelKind::NaiveNet`: the naive force from the small network of thesis 2.4.
    pub const NAIVE_NET: u32 = 3;
    /// friction-net with a contact-frame network (`NetKind::FrictionContact`).
    pub const FRICTION_CONTACT_NET: u32 = 4;
}

/// The kind of level a multigrid pipeline's dispatches work on, its WGSL
/// override `LEVEL` (`gpu::kernels::LevelKind`).
pub mod level {
    /// Read from the bound hop (`multigrid::tail`, which walks them all).
    pub const ANY: u32 = 0;
    /// The cloth, level 0.
    pub const CLOTH: u32 = 1;
    /// A coarse level.
    pub const COARSE: u32 = 2;
}

// `pcg::stop_levels` zeroes level l's sizes from invocation l of a workgroup.
const _: () = assert!(multigrid::MAX_LEVELS <= WORKGROUP);

/// Every constant the kernels read, by its WGSL name (`model::NAIVE_NET`
/// and `motion::STATIC` are the kernels' `else` branches, so they never
/// name them, nor `level::COARSE`).
pub const SHARED: &[(&str, u32)] = &[
    ("WORKGROUP", WORKGROUP),
    ("CONTACT_FRAME_ROWS", CONTACT_FRAME_ROWS),
    ("WORLD_FRAME_ROWS", WORLD_FRAME_ROWS),
    ("BATCH_GROUP", BATCH_GROUP),
    ("NO_TRIANGLE", NO_TRIANGLE),
    ("TILE", TILE),
    ("FACE_VERTEX_LANES", FACE_VERTEX_LANES),
    ("EDGE_PAIR", separate::EDGE_PAIR),
    ("SEP_LEAST", separations::LEAST),
    ("SEP_FLAGS", separations::FLAGS),
    ("SEP_COUNT", separations::COUNT),
    ("SEP_LABEL", separations::LABEL),
    ("SEP_NEXT", separations::NEXT),
    ("SEP_ANCHOR", separations::ANCHOR),
    ("SEP_STEP", separations::STEP),
    ("SEP_SUM", separations::SUM),
    ("SEP_SWEPT", separations::SWEPT),
    ("SEP_WORDS", separations::WORDS),
    ("FLAG_HELD", separations::HELD),
    ("FLAG_HELD_NEW", separations::HELD_NEW),
    ("FLAG_PUSHED", separations::PUSHED),
    ("FLAG_ZONED", separations::ZONED),
    ("FLAG_BODY", separations::BODY),
    ("ANCHOR_BODY", separations::ANCHOR_BODY),
    ("SELF_PAIR_COUNT", self_header::PAIR_COUNT),
    ("SELF_FAILING", self_header::FAILING),
    ("SELF_CHANGED", self_header::CHANGED),
    ("SELF_UNSETTLED", self_header::UNSETTLED),
    ("SELF_SETTLED", self_header::SETTLED),
    ("SELF_FIRST", self_header::FIRST),
    ("SELF_LAST_RESORT", self_header::LAST_RESORT),
    ("SELF_DETECTED", self_header::DETECTED),
    ("SELF_MOST_PAIRS", self_header::MOST_PAIRS),
    ("SELF_PREPARE_ARGS", self_header::PREPARE_ARGS),
    ("SELF_TILES_ARGS", self_header::TILES_ARGS),
    ("SELF_SUPERTILES_ARGS", self_header::SUPERTILES_ARGS),
    ("SELF_WALKS_ARGS", self_header::WALKS_ARGS),
    ("SELF_LIST_ARGS", self_header::LIST_ARGS),
    ("SELF_RETEST_ARGS", self_header::RETEST_ARGS),
    ("SELF_VERTEX_ARGS", self_header::VERTEX_ARGS),
    ("SELF_ROUND_ARGS", self_header::ROUND_ARGS),
    ("SELF_SETTLE_ARGS", self_header::SETTLE_ARGS),
    ("SELF_RECHECK_ARGS", self_header::RECHECK_ARGS),
    ("CLOTH_COUNT", cloth_header::COUNT),
    ("CLOTH_DROPPED", cloth_header::DROPPED),
    ("CLOTH_HEADER", cloth_header::WORDS),
    ("MOTION_LINEAR", motion::LINEAR),
    ("MOTION_SINUSOID", motion::SINUSOID),
    ("MODEL_NAIVE", model::NAIVE),
    ("MODEL_FRICTION", model::FRICTION),
    ("MODEL_FRICTION_NET", model::FRICTION_NET),
    ("MODEL_FRICTION_CONTACT_NET", model::FRICTION_CONTACT_NET),
    ("NOT_FINITE", health::NOT_FINITE),
    ("TOO_FAST", health::TOO_FAST),
    ("STENCIL", multigrid::STENCIL),
    ("STORED_STENCIL", multigrid::STORED_STENCIL),
    ("COARSEST_NODES", multigrid::COARSEST_NODES),
    ("COARSE_SWEEPS", multigrid::COARSE_SWEEPS),
    ("MAX_LEVELS", multigrid::MAX_LEVELS),
    ("PATCH", multigrid::PATCH),
    ("PATCH_COLOURS", multigrid::PATCH_COLOURS as u32),
    ("PATCH_BLOCKS", multigrid::PATCH_BLOCKS),
    ("NO_PATCHES", multigrid::NO_PATCHES),
    ("LEVEL_ANY", level::ANY),
    ("LEVEL_CLOTH", level::CLOTH),
    // Set per device (`Kernels::new`); this is the declared default.
    ("MLP_THREADS", 16),
];

/// The `f32` constants the kernels read, by their WGSL names.
pub const SHARED_F32: &[(&str, f32)] = &[
    ("SLIDE_AT_REST", contact::SLIDE_AT_REST),
    ("STICK_LOG_MAX", contact::STICK_LOG_MAX),
    ("SMOOTH_WEIGHT", multigrid::SMOOTH_WEIGHT),
    ("SMOOTH_MARGIN", multigrid::SMOOTH_MARGIN),
    ("FIXED_UNITS", impact::UNITS),
    ("FIXED_LARGEST", impact::LARGEST),
];

/// The WGSL declarations of [`SHARED`] and [`SHARED_F32`], with the
/// network tile's threads per edge chosen for the device.
pub fn prelude(mlp_threads: u32) -> String {
    let integers = SHARED.iter().map(|&(name, value)| {
        let value = if name == "MLP_THREADS" {
            mlp_threads
        } else {
            value
        };
        format!("const {name}: u32 = {value}u;\n")
    });
    // The f32's value, exact in f64, with the digits that read back as it
    // (an f32's own shortest digits may not: 2^32 prints as 4294967300).
    let floats = SHARED_F32
        .iter()
        .map(|&(name, value)| format!("const {name}: f32 = {:?};\n", value as f64));
    integers.chain(floats).collect()
}
