//! Sharding of numbered work (episodes of a generation or an evaluation) over independent
//! processes, e.g. the tasks of a Slurm array job: shard `I/N` owns the items k with k mod N = I,
//! so the shards' outputs together are exactly an unsharded run's.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// Shard `index` of `count` (`I/N` on command lines, 0 ≤ I < N); `0/1` is the whole run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Shard {
    /// This shard's position, 0-based (Slurm's `SLURM_ARRAY_TASK_ID` for an array `0-(N-1)`).
    pub index: usize,
    /// Number of shards.
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Shard::WHOLE
    }
}

impl Shard {
    /// The whole run: one shard.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Shard `index` of `count`; an error unless `index < count`.
    pub fn new(index: usize, count: usize) -> Result<Self, String> {
        if count == 0 || index >= count {
            return Err(format!(
                "shard {index}/{count}: need 0 ≤ I < N (I/N, e.g. 0/4 … 3/4)"
            ));
        }
        Ok(Shard { index, count })
    }

    /// Whether this shard is the whole run.
    pub fn is_whole(&self) -> bool {
        self.count == 1
    }

    /// Whether item `k` belongs to this shard.
    pub fn owns(&self, k: usize) -> bool {
        k % self.count == self.index
    }

    /// This shard's items among `0..items`, in increasing order.
    pub fn items(&self, items: usize) -> Vec<usize> {
        (self.index..items).step_by(self.count).collect()
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("shard `{s}`: expected I/N with 0 ≤ I < N, e.g. 0/4");
        let (i, n) = s.trim().split_once('/').ok_or_else(bad)?;
        let i = i.trim().parse::<usize>().map_err(|_| bad())?;
        let n = n.trim().parse::<usize>().map_err(|_| bad())?;
        Shard::new(i, n).map_err(|_| bad())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn parses_and_prints() {
        let s: Shard = "2/5".parse().unwrap();
        assert_eq!(s, Shard { index: 2, count: 5 });
        assert_eq!(s.to_string(), "2/5");
        assert_eq!(s.items(13), vec![2, 7, 12]);
        assert!(s.owns(7) && !s.owns(8));
        assert!(Shard::WHOLE.is_whole());
        assert_eq!(Shard::WHOLE.items(3), vec![0, 1, 2]);
        for bad in ["5/5", "1/0", "3", "a/2", "-1/2", "1/2/3", ""] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains("expected I/N"), "{bad}: {e}");
        }
    }

    proptest! {
        /// The shards of a run partition its items: each item in exactly one shard.
        #[test]
        fn shards_partition_the_items(items in 0usize..200, count in 1usize..9) {
            let mut seen = vec![0u8; items];
            for index in 0..count {
                let s = Shard::new(index, count).unwrap();
                for k in s.items(items) {
                    prop_assert!(s.owns(k));
                    seen[k] += 1;
                }
            }
            prop_assert!(seen.iter().all(|&c| c == 1));
        }

        /// Parsing never panics, and what parses prints back the same.
        #[test]
        fn parse_round_trips(s in "[0-9/ ]{0,8}") {
            if let Ok(sh) = s.parse::<Shard>() {
                prop_assert_eq!(sh.to_string().parse::<Shard>().unwrap(), sh);
            }
        }
    }
}
