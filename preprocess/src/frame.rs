//! The in-memory particle frame every reader produces and the hierarchy builder consumes.
//!
//! A [`Frame`] is one timestep of one simulation: positions in the simulation's own
//! length unit, a species index per particle into [`Frame::species`], an optional scalar
//! attribute, and what the dump said about the box, the timestep and the units.

pub use mdlod_format::meta::SimulationBox;

/// One species (atom type or element) as named in the input.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SpeciesName {
    /// Element symbol (`Cu`), LAMMPS numeric type as text (`1`), or the XYZ species label.
    pub name: String,
    /// True when `name` is a number from a column of numbers only: a LAMMPS `type`
    /// column with no element given, an XYZ species column of numbers, MMPLD list numbers.
    pub numeric_type: bool,
    /// The radius the input gives this species (GSD `particles/diameter` / 2), used
    /// unless the user overrides it.
    pub radius: Option<f32>,
    /// The smallest and largest radius of the species' particles where the input gives
    /// each particle its own ([`Frame::radii`]) and they differ: `radius` is then their
    /// mean, and the file keeps each particle's own.
    pub radius_range: Option<(f32, f32)>,
    /// The colour the input gives this species (sRGB bytes: an MMPLD list's global
    /// colour), used instead of the element's or the palette's.
    pub colour: Option<[u8; 3]>,
    /// How many particles gave `radius` (their mean) and `radius_range` from their own
    /// sizes (a text dump's size column), and the sum of their radii, so that parts of a
    /// frame read apart combine into the whole frame's mean exactly; 0 otherwise.
    pub sized_count: u64,
    pub sized_sum: f64,
    /// The species' place in the palette by the input's own numbering (LAMMPS type
    /// `n`: `n − 1`), so that a type keeps its colour in frames that lack others; the
    /// place in the frame's list when `None`.
    pub palette_slot: Option<usize>,
}

/// One timestep of particles, as read from a dump.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    /// Particle centres, in the simulation's length unit, unwrapped/scaled columns already
    /// converted to Cartesian coordinates.
    pub positions: Vec<[f32; 3]>,
    /// Index into `species` for every particle (same length as `positions`).
    pub species_index: Vec<u16>,
    /// The distinct species in order of first appearance (numeric types, LAMMPS or XYZ,
    /// sorted numerically instead).
    pub species: Vec<SpeciesName>,
    /// Optional per-particle scalar (a named dump column), same length as `positions`.
    pub attribute: Option<Attribute>,
    /// Each particle's own radius, where the input gives one (GSD diameters / 2, MMPLD
    /// `xyzr` lists, a dump's `radius` or `diameter` column), same length as
    /// `positions`. A conversion keeps them where some species' particles differ in
    /// size (see [`SpeciesName::radius_range`]).
    pub radii: Option<Vec<f32>>,
    /// The simulation cell, when the dump has one.
    pub simulation_box: Option<SimulationBox>,
    /// The MD timestep number, when known.
    pub timestep: Option<u64>,
    /// Simulation time, when the dump records it (LAMMPS `ITEM: TIME`, XYZ `Time=`).
    pub time: Option<f64>,
    /// Unit style, when the dump records it (LAMMPS `ITEM: UNITS`).
    pub units: Option<String>,
}

/// A named per-particle scalar column.
#[derive(Clone, Debug, PartialEq)]
pub struct Attribute {
    pub name: String,
    pub values: Vec<f32>,
}

impl Frame {
    /// A frame with this one's box, timestep, time and units and no particles.
    pub fn clone_header(&self) -> Frame {
        Frame {
            simulation_box: self.simulation_box.clone(),
            timestep: self.timestep,
            time: self.time,
            units: self.units.clone(),
            ..Default::default()
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}
