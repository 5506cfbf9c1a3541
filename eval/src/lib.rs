//! Closed-loop evaluation. (Not built yet: see the eval issue.)
