//! The stages of one step, in order. Each is a module of src/cpu/ and a
//! pass of a wgsl/ file with the same name; `stage_ms` in reports and the
//! per-stage benches use these names.

/// Declares [`Stage`], [`Stage::ALL`] and [`Stage::name`] from one list,
/// in the order a step runs the stages.
macro_rules! stages {
    ($($(#[$doc:meta])* $stage:ident => $name:literal,)*) => {
        /// A stage of the step, on either backend.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum Stage {
            $($(#[$doc])* $stage,)*
        }

        impl Stage {
            /// Every stage, in the order a step runs them.
            pub const ALL: [Stage; [$($name),*].len()] = [$(Stage::$stage),*];

            /// The stage's name: its cpu/ module, its wgsl/ file and its
            /// `stage_ms` key.
            pub const fn name(self) -> &'static str {
                match self {
                    $(Stage::$stage => $name,)*
                }
            }
        }
    };
}

stages! {
    /// Places the rigid body at the end of the step.
    Rigid => "rigid",
    /// Vertex–face and face–vertex contacts.
    Collide => "collide",
    /// The contact model's forces and Jacobians (eqs. 6, 8, 9, or a network).
    Contact => "contact",
    /// The spring forces and stiffness blocks (eqs. 4–5) and the backward
    /// Euler system A v' = b.
    Assemble => "assemble",
    /// The cloth's contacts with itself and their eqs. 8–9 forces and
    /// blocks added to the system (issue 23), when `self_contact` is on
    /// with a thickness.
    SelfContact => "self_contact",
    /// Preconditioned CG (multigrid or Jacobi).
    Pcg => "pcg",
    /// The normal force each vertex's cloth–cloth contacts carried in the
    /// solve, which bounds the next step's friction, when stage
    /// "self_contact" runs.
    Load => "load",
    /// x' = x + h v'.
    Integrate => "integrate",
    /// The deepest penetration into the body after the solve, then the
    /// push-out of the vertices inside it.
    Measure => "measure",
    /// The failsafe for what the self-contact forces miss: impulses that
    /// keep momentum and obey Coulomb, then impact zones (issue 65), when
    /// `self_contact` is on.
    Separate => "separate",
}

impl Stage {
    /// Position in [`Stage::ALL`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Whether a step of a scene runs this stage: the rigid-body stages
    /// only with a body, [`Stage::Separate`] only with self-contact on,
    /// [`Stage::SelfContact`] and [`Stage::Load`] only with its forces too.
    pub const fn runs(self, has_body: bool, self_contact: SelfContactStages) -> bool {
        match self {
            Stage::Rigid | Stage::Collide | Stage::Contact | Stage::Measure => has_body,
            Stage::Separate => self_contact.separate,
            Stage::SelfContact | Stage::Load => self_contact.forces,
            Stage::Assemble | Stage::Pcg | Stage::Integrate => true,
        }
    }
}

/// Which self-contact stages a scene runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SelfContactStages {
    /// [`Stage::Separate`]: `self_contact.enabled`.
    pub separate: bool,
    /// [`Stage::SelfContact`]: enabled with a thickness above 0.
    pub forces: bool,
}

impl SelfContactStages {
    /// The stages `[self_contact]` asks for.
    pub fn of(config: &crate::config::SelfContactConfig) -> SelfContactStages {
        SelfContactStages {
            separate: config.enabled,
            forces: config.enabled && config.thickness > 0.0,
        }
    }
}
