//! Helpers for the command line and examples: throughput figures ([`bench`](mod@bench)) and contact sheets of
//! rendered frames ([`sheet`]).

pub mod bench;
pub mod sheet;
