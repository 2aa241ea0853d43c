//! How the CPU path splits its passes among rayon's threads.

/// Smallest slice a rayon task gets: below this, splitting costs more than
/// the work (a 32² cloth's vectors stay on one thread).
pub const GRAIN: usize = 2048;
