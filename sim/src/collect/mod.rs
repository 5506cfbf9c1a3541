//! Collecting data with the expert: episode recording to mcap ([`record`]), dataset generation
//! ([`generate`]) and the perceptual-aliasing measurement of expert episodes ([`aliasing`]).

pub mod aliasing;
pub mod generate;
pub mod record;
