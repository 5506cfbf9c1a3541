//! Collecting data with the expert: episode recording to mcap ([`record`]) with LIBERO-Mem's
//! per-object subgoal labels ([`labels`]), dataset generation
//! ([`generate`]) and the perceptual-aliasing measurement of expert episodes ([`aliasing`]).

pub mod aliasing;
pub mod generate;
pub mod labels;
pub mod record;
