//! LIBERO's predicates evaluated on the simulator state (libero.md §2), with its exact rules and quirks:
//! `under()` multiplies by R (not Rᵀ), `in_box()` uses |R·h| as the half-extent, `On(a, b)` between objects
//! needs contact, b below a and xy distance < 3 cm, and so on.

use crate::engine::mujoco::Data;
use crate::task::Predicate;
use crate::world::scene::{Scene, SceneRegion};

/// Errors from predicate evaluation.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PredicateError {
    /// A predicate LIBERO does not register.
    #[error(
        "unknown predicate '{0}' (known: true, false, on, in, up, open, close, turnon, turnoff)"
    )]
    Unknown(String),
    /// Wrong number of arguments.
    #[error("predicate '{0}' takes {1} argument(s), got {2}")]
    Arity(String, usize, usize),
    /// An argument naming neither an instance nor a region with a site.
    #[error("'{0}' is neither an object, a fixture nor a region of this task")]
    UnknownEntity(String),
    /// A combination LIBERO cannot evaluate either (it raises).
    #[error("{0}")]
    Unsupported(String),
}

/// A predicate as [`Predicates::eval`] takes it: a parsed [`Predicate`] or its name (any case).
pub trait PredicateRef {
    /// The predicate, or [`PredicateError::Unknown`] for a name LIBERO does not register.
    fn predicate(&self) -> Result<Predicate, PredicateError>;
}

impl PredicateRef for Predicate {
    fn predicate(&self) -> Result<Predicate, PredicateError> {
        Ok(*self)
    }
}

impl PredicateRef for &Predicate {
    fn predicate(&self) -> Result<Predicate, PredicateError> {
        Ok(**self)
    }
}

impl PredicateRef for &str {
    fn predicate(&self) -> Result<Predicate, PredicateError> {
        let name = self.to_ascii_lowercase();
        Predicate::from_name(&name).ok_or(PredicateError::Unknown(name))
    }
}

/// Default object height used by `under()`.
const OBJECT_HEIGHT: f64 = 0.10;

enum Entity<'a> {
    Instance(usize),
    Site(usize, &'a SceneRegion),
}

/// Evaluates predicates on one state of one scene.
pub struct Predicates<'a> {
    scene: &'a Scene,
    data: &'a Data,
}

impl<'a> Predicates<'a> {
    /// A view of `data` (which must be after a forward pass or a step) for `scene`.
    pub fn new(scene: &'a Scene, data: &'a Data) -> Self {
        Predicates { scene, data }
    }

    fn entity(&self, name: &str) -> Result<Entity<'a>, PredicateError> {
        if let Some(i) = self.scene.instance(name) {
            return Ok(Entity::Instance(i));
        }
        match self.scene.regions.get(name) {
            Some(r) => match r.site {
                Some(s) => Ok(Entity::Site(s, r)),
                None => Err(PredicateError::UnknownEntity(name.to_string())),
            },
            None => Err(PredicateError::UnknownEntity(name.to_string())),
        }
    }

    fn pos(&self, e: &Entity) -> [f64; 3] {
        match e {
            Entity::Instance(i) => self.data.body_pos(self.scene.instances[*i].root_body),
            Entity::Site(s, _) => self.data.site_pos(*s),
        }
    }

    /// True if any active contact pairs a geom of instance `a` with a geom of instance `b`.
    pub fn contact(&self, a: usize, b: usize) -> bool {
        let (ga, gb) = (
            &self.scene.instances[a].geoms,
            &self.scene.instances[b].geoms,
        );
        self.data.contacts().iter().any(|c| {
            (ga.contains(&c.geom1) && gb.contains(&c.geom2))
                || (ga.contains(&c.geom2) && gb.contains(&c.geom1))
        })
    }

    /// `under(s, p)`: d = R·(p − pos(s)); h.z − 0.005 < d.z < h.z + 0.10, |d.x| < h.x, |d.y| < h.y.
    pub fn under(&self, site: usize, p: [f64; 3]) -> bool {
        let c = self.data.site_pos(site);
        let r = self.data.site_mat(site);
        let h = self.scene.model.site_size(site);
        let v = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let d = mat_vec(&r, v);
        h[2] - 0.005 < d[2] && d[2] < h[2] + OBJECT_HEIGHT && d[0].abs() < h[0] && d[1].abs() < h[1]
    }

    /// `in_box(s, p)`: e = |R·h|; pos − e (z lowered by 0.01 more) < p < pos + e, strictly.
    pub fn in_box(&self, site: usize, p: [f64; 3]) -> bool {
        let c = self.data.site_pos(site);
        let r = self.data.site_mat(site);
        let h = self.scene.model.site_size(site);
        let e = mat_vec(&r, h).map(f64::abs);
        let lb = [c[0] - e[0], c[1] - e[1], c[2] - e[2] - 0.01];
        let ub = [c[0] + e[0], c[1] + e[1], c[2] + e[2]];
        (0..3).all(|k| lb[k] < p[k] && p[k] < ub[k])
    }

    fn joints_of(&self, e: &Entity) -> Vec<(usize, usize, crate::world::assets::Articulation)> {
        match e {
            Entity::Instance(i) => self.scene.instances[*i].joints.clone(),
            Entity::Site(_, r) => r.joints.clone(),
        }
    }

    /// Evaluates `(predicate args…)`; a predicate given by name is matched case-insensitively.
    pub fn eval(
        &self,
        predicate: impl PredicateRef,
        args: &[String],
    ) -> Result<bool, PredicateError> {
        let p = predicate.predicate()?;
        let arity = |n: usize| {
            if args.len() == n {
                Ok(())
            } else {
                Err(PredicateError::Arity(p.name().to_string(), n, args.len()))
            }
        };
        match p {
            Predicate::True => Ok(true),
            Predicate::False => Ok(false),
            Predicate::On => {
                arity(2)?;
                let a = self.entity(&args[0])?;
                let Entity::Instance(ai) = a else {
                    return Err(PredicateError::Unsupported(format!(
                        "On: '{}' is a region",
                        args[0]
                    )));
                };
                let pa = self.pos(&a);
                match self.entity(&args[1])? {
                    Entity::Instance(bi) => {
                        let pb = self.data.body_pos(self.scene.instances[bi].root_body);
                        let dxy = ((pa[0] - pb[0]).powi(2) + (pa[1] - pb[1]).powi(2)).sqrt();
                        Ok(pb[2] <= pa[2] && dxy < 0.03 && self.contact(bi, ai))
                    }
                    Entity::Site(s, r) => {
                        let under = self.under(s, pa);
                        Ok(under && r.parent.is_none_or(|pi| self.contact(pi, ai)))
                    }
                }
            }
            Predicate::In => {
                arity(2)?;
                let a = self.entity(&args[0])?;
                let pa = self.pos(&a);
                match self.entity(&args[1])? {
                    Entity::Site(s, _) => Ok(self.in_box(s, pa)),
                    Entity::Instance(bi) => match a {
                        Entity::Instance(ai) if self.contact(ai, bi) => {
                            Err(PredicateError::Unsupported(format!(
                                "In({}, {}): LIBERO cannot evaluate In with an object as container while they touch; use the object's contain_region",
                                args[0], args[1]
                            )))
                        }
                        _ => Ok(false),
                    },
                }
            }
            Predicate::Up => {
                arity(1)?;
                let a = self.entity(&args[0])?;
                Ok(self.pos(&a)[2] >= 1.0)
            }
            Predicate::Open | Predicate::Close | Predicate::TurnOn | Predicate::TurnOff => {
                arity(1)?;
                let e = self.entity(&args[0])?;
                let joints = self.joints_of(&e);
                if joints.is_empty() {
                    return Err(PredicateError::Unsupported(format!(
                        "{p}: '{}' has no joints",
                        args[0]
                    )));
                }
                let q = self.data.qpos();
                Ok(match p {
                    Predicate::Open => joints.iter().any(|&(_, a, art)| art.is_open(q[a])),
                    Predicate::Close => joints.iter().all(|&(_, a, art)| art.is_close(q[a])),
                    Predicate::TurnOn => joints.iter().any(|&(_, a, art)| art.turn_on(q[a])),
                    Predicate::TurnOff => joints.iter().all(|&(_, a, art)| art.turn_off(q[a])),
                    other => unreachable!("{other} is not an articulation predicate"),
                })
            }
            // LIBERO registers it but its evaluator does not know it.
            Predicate::PrintJointState => Err(PredicateError::Unknown(p.name().to_string())),
        }
    }
}

fn mat_vec(r: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    [
        r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
        r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
        r[6] * v[0] + r[7] * v[1] + r[8] * v[2],
    ]
}
