//! Writing a loaded scene in other programs' input formats, so the same scene can be rendered
//! by them side by side with icrender (no rendering logic here).

pub mod radiance;
