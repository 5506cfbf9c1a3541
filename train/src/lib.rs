//! Training loop. (Not built yet: see the train issue.)
