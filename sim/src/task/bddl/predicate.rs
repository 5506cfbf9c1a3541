//! LIBERO's predicate registry (libero.md §2.1) as a closed enum: each predicate's name, its BDDL
//! spelling and how many arguments it takes. A new predicate is a new variant, and every `match` on
//! [`Predicate`] (parser, printer, goal text, evaluation on the simulator, scene sampling, expert
//! planning) then fails to compile until it handles it.

use std::fmt;

/// A predicate of LIBERO's registry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Predicate {
    /// `(True …)`: always holds (arguments ignored).
    True,
    /// `(False …)`: never holds (arguments ignored).
    False,
    /// `(In a region)`: `a` inside a region's box.
    In,
    /// `(On a b)`: `a` resting on object `b` or inside region `b`.
    On,
    /// `(Up a)`: `a` lifted above its initial height.
    Up,
    /// `(PrintJointState a)`: LIBERO's debugging predicate (prints, holds).
    PrintJointState,
    /// `(Open a)`: an articulated region (drawer, door) open.
    Open,
    /// `(Close a)`: an articulated region closed.
    Close,
    /// `(TurnOn a)`: a stove's knob turned on.
    TurnOn,
    /// `(TurnOff a)`: a stove's knob turned off.
    TurnOff,
}

impl Predicate {
    /// Every predicate, in LIBERO's registry order (the order error messages list them in).
    pub const ALL: [Predicate; 10] = [
        Predicate::True,
        Predicate::False,
        Predicate::In,
        Predicate::On,
        Predicate::Up,
        Predicate::PrintJointState,
        Predicate::Open,
        Predicate::Close,
        Predicate::TurnOn,
        Predicate::TurnOff,
    ];

    /// The lowercase name BDDL files are read as (`on`, `turnon`, …).
    pub const fn name(self) -> &'static str {
        match self {
            Predicate::True => "true",
            Predicate::False => "false",
            Predicate::In => "in",
            Predicate::On => "on",
            Predicate::Up => "up",
            Predicate::PrintJointState => "printjointstate",
            Predicate::Open => "open",
            Predicate::Close => "close",
            Predicate::TurnOn => "turnon",
            Predicate::TurnOff => "turnoff",
        }
    }

    /// The name as the printer writes it: first letter capitalised (`On`, `Turnon`), as LIBERO reads
    /// it back.
    pub const fn bddl_name(self) -> &'static str {
        match self {
            Predicate::True => "True",
            Predicate::False => "False",
            Predicate::In => "In",
            Predicate::On => "On",
            Predicate::Up => "Up",
            Predicate::PrintJointState => "Printjointstate",
            Predicate::Open => "Open",
            Predicate::Close => "Close",
            Predicate::TurnOn => "Turnon",
            Predicate::TurnOff => "Turnoff",
        }
    }

    /// Least and most arguments accepted (`true`/`false` ignore theirs).
    pub const fn arity(self) -> (usize, usize) {
        match self {
            Predicate::True | Predicate::False => (0, 2),
            Predicate::In | Predicate::On => (2, 2),
            Predicate::Up
            | Predicate::PrintJointState
            | Predicate::Open
            | Predicate::Close
            | Predicate::TurnOn
            | Predicate::TurnOff => (1, 1),
        }
    }

    /// The predicate of a lowercase name, `None` if LIBERO does not register it.
    pub fn from_name(name: &str) -> Option<Predicate> {
        Predicate::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Same as [`Predicate::name`].
    pub const fn as_str(self) -> &'static str {
        self.name()
    }
}

impl fmt::Display for Predicate {
    /// The lowercase name.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// LIBERO's predicate registry as (name, least, most arguments), in [`Predicate::ALL`]'s order.
pub const PREDICATES: [(&str, usize, usize); 10] = {
    let mut out = [("", 0, 0); 10];
    let mut i = 0;
    while i < out.len() {
        let p = Predicate::ALL[i];
        let (lo, hi) = p.arity();
        out[i] = (p.name(), lo, hi);
        i += 1;
    }
    out
};
