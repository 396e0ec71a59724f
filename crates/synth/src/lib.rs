//! The synthetic motion-blur benchmark generator (mesh renderer, room, moving body, events, ground-truth flow)
