//! Episodes on disk: schema, mcap I/O, RLDS import, windows. (Not built yet: see the data issue.)
