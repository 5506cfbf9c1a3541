//! Embodied-SlotSSM and its baselines in Burn. (Not built yet: see the model issue.)
