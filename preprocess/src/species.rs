//! Default looks of species: radii by element from a table of standard atomic radii, a
//! palette for numeric LAMMPS types, and user overrides (`--radius Cu=1.28`).

use mdlod_format::meta::Species;

use crate::frame::SpeciesName;

/// (symbol, atomic radius in Å, sRGB colour as commonly used by molecular viewers).
const ELEMENTS: &[(&str, f32, [u8; 3])] = &[
    ("H", 0.46, [255, 255, 255]),
    ("He", 1.22, [217, 255, 255]),
    ("Li", 1.57, [204, 128, 255]),
    ("Be", 1.12, [194, 255, 0]),
    ("B", 0.88, [255, 181, 181]),
    ("C", 0.77, [144, 144, 144]),
    ("N", 0.74, [48, 80, 248]),
    ("O", 0.74, [255, 13, 13]),
    ("F", 0.72, [144, 224, 80]),
    ("Ne", 1.60, [179, 227, 245]),
    ("Na", 1.91, [171, 92, 242]),
    ("Mg", 1.60, [138, 255, 0]),
    ("Al", 1.43, [191, 166, 166]),
    ("Si", 1.18, [240, 200, 160]),
    ("P", 1.10, [255, 128, 0]),
    ("S", 1.04, [255, 255, 48]),
    ("Cl", 0.99, [31, 240, 31]),
    ("Ar", 1.92, [128, 209, 227]),
    ("K", 2.35, [143, 64, 212]),
    ("Ca", 1.97, [61, 255, 0]),
    ("Ti", 1.47, [191, 194, 199]),
    ("V", 1.34, [166, 166, 171]),
    ("Cr", 1.28, [138, 153, 199]),
    ("Mn", 1.27, [156, 122, 199]),
    ("Fe", 1.26, [224, 102, 51]),
    ("Co", 1.25, [240, 144, 160]),
    ("Ni", 1.24, [80, 208, 80]),
    ("Cu", 1.28, [200, 128, 51]),
    ("Zn", 1.34, [125, 128, 176]),
    ("Ga", 1.35, [194, 143, 143]),
    ("Ge", 1.22, [102, 143, 143]),
    ("Kr", 1.98, [92, 184, 209]),
    ("Zr", 1.60, [148, 224, 224]),
    ("Nb", 1.46, [115, 194, 201]),
    ("Mo", 1.39, [84, 181, 181]),
    ("Pd", 1.37, [0, 105, 133]),
    ("Ag", 1.44, [192, 192, 192]),
    ("Sn", 1.58, [102, 128, 128]),
    ("Xe", 2.18, [66, 158, 176]),
    ("Ta", 1.46, [77, 166, 255]),
    ("W", 1.39, [33, 148, 214]),
    ("Pt", 1.39, [208, 208, 224]),
    ("Au", 1.44, [255, 209, 35]),
    ("Pb", 1.75, [87, 89, 97]),
    ("U", 1.56, [0, 143, 255]),
    // Further elements of salts, semiconductors and biomolecules (colours as Jmol's;
    // metallic radii for metals, covalent ones otherwise, as above).
    ("Sc", 1.64, [230, 230, 230]),
    ("As", 1.21, [189, 128, 227]),
    ("Se", 1.16, [255, 161, 0]),
    ("Br", 1.14, [166, 41, 41]),
    ("Rb", 2.48, [112, 46, 176]),
    ("Sr", 2.15, [0, 255, 0]),
    ("Y", 1.80, [148, 255, 255]),
    ("Ru", 1.34, [36, 143, 143]),
    ("Rh", 1.34, [10, 125, 140]),
    ("Cd", 1.51, [255, 217, 143]),
    ("In", 1.67, [166, 117, 115]),
    ("Sb", 1.45, [158, 99, 181]),
    ("Te", 1.40, [212, 122, 0]),
    ("I", 1.33, [148, 0, 148]),
    ("Cs", 2.67, [87, 23, 143]),
    ("Ba", 2.22, [0, 201, 0]),
    ("La", 1.87, [112, 212, 255]),
    ("Ce", 1.83, [255, 255, 199]),
    ("Nd", 1.82, [199, 255, 199]),
    ("Gd", 1.80, [69, 255, 199]),
    ("Hf", 1.59, [77, 194, 255]),
    ("Re", 1.37, [38, 125, 171]),
    ("Os", 1.35, [38, 102, 150]),
    ("Ir", 1.36, [23, 84, 135]),
    ("Hg", 1.51, [184, 184, 208]),
    ("Tl", 1.70, [166, 84, 77]),
    ("Bi", 1.55, [158, 79, 181]),
    // Metallic radii (coordination 12) where measured; the heaviest, estimated.
    ("Tc", 1.36, [59, 158, 158]),
    ("Pr", 1.82, [217, 255, 199]),
    ("Pm", 1.83, [163, 255, 199]),
    ("Sm", 1.80, [143, 255, 199]),
    ("Eu", 2.04, [97, 255, 199]),
    ("Tb", 1.78, [48, 255, 199]),
    ("Dy", 1.77, [31, 255, 199]),
    ("Ho", 1.76, [0, 255, 156]),
    ("Er", 1.75, [0, 230, 117]),
    ("Tm", 1.74, [0, 212, 82]),
    ("Yb", 1.94, [0, 191, 56]),
    ("Lu", 1.73, [0, 171, 36]),
    ("Po", 1.68, [171, 92, 0]),
    ("At", 1.50, [117, 79, 69]),
    ("Rn", 2.20, [66, 130, 150]),
    ("Fr", 2.70, [66, 0, 102]),
    ("Ra", 2.23, [0, 125, 0]),
    ("Ac", 1.88, [112, 171, 250]),
    ("Th", 1.80, [0, 186, 255]),
    ("Pa", 1.63, [0, 161, 255]),
    ("Np", 1.55, [0, 128, 255]),
    ("Pu", 1.59, [0, 107, 255]),
    ("Am", 1.73, [84, 92, 242]),
    ("Cm", 1.74, [120, 92, 227]),
    ("Bk", 1.70, [138, 79, 227]),
    ("Cf", 1.86, [161, 54, 212]),
    ("Es", 1.86, [179, 31, 212]),
    ("Fm", 1.80, [179, 31, 186]),
    ("Md", 1.80, [179, 13, 166]),
    ("No", 1.80, [189, 13, 135]),
    ("Lr", 1.80, [199, 0, 102]),
    ("Rf", 1.50, [204, 0, 89]),
    ("Db", 1.50, [209, 0, 79]),
    ("Sg", 1.50, [217, 0, 69]),
    ("Bh", 1.50, [224, 0, 56]),
    ("Hs", 1.50, [230, 0, 46]),
    ("Mt", 1.50, [235, 0, 38]),
    ("Ds", 1.50, [235, 0, 38]),
    ("Rg", 1.50, [235, 0, 38]),
    ("Cn", 1.50, [235, 0, 38]),
    ("Nh", 1.50, [235, 0, 38]),
    ("Fl", 1.50, [235, 0, 38]),
    ("Mc", 1.50, [235, 0, 38]),
    ("Lv", 1.50, [235, 0, 38]),
    ("Ts", 1.50, [235, 0, 38]),
    ("Og", 1.50, [235, 0, 38]),
];

pub use mdlod_format::meta::{palette_colour, palette_colour_linear};

/// The colour (sRGB) of a category of `--species-column` `column` by its value, the same
/// in every frame. Structure types take the colours OVITO gives fcc (green), hcp (red),
/// bcc (blue) and icosahedral (gold) atoms, and unknown or other ones light grey, by the
/// numbers of the LAMMPS compute the column's name names ([`structure_kind`]):
/// `cna/atom` 1 fcc, 2 hcp, 3 bcc, 4 ico, 0 and 5 other; `ptm/atom` the same with 0
/// other and 5 on (simple cubic, diamond, ...) the palette's; `ackland/atom` 1 bcc, 2 fcc,
/// 3 hcp, 4 ico, 0 unknown. Any other column (a molecule id) takes the palette's by value,
/// as light grey on white would hide a molecule. `None` below 0 (coloured by place).
pub fn category_colour(column: &str, value: i64) -> Option<[u8; 3]> {
    const GREY: [u8; 3] = [242, 242, 242];
    const FCC: [u8; 3] = [102, 255, 102];
    const HCP: [u8; 3] = [255, 102, 102];
    const BCC: [u8; 3] = [102, 102, 255];
    const ICO: [u8; 3] = [242, 204, 51];
    let palette = |v: i64| usize::try_from(v).ok().map(palette_colour);
    let Some(kind) = structure_kind(column) else {
        return palette(value);
    };
    Some(match (kind, value) {
        (_, v) if v < 0 => return None,
        (Structure::Ackland, 0) => GREY,
        (Structure::Ackland, 1) => BCC,
        (Structure::Ackland, 2) => FCC,
        (Structure::Ackland, 3) => HCP,
        (Structure::Ackland, 4) => ICO,
        (Structure::Cna, 0 | 5) | (Structure::Ptm, 0) => GREY,
        (Structure::Cna | Structure::Ptm, 1) => FCC,
        (Structure::Cna | Structure::Ptm, 2) => HCP,
        (Structure::Cna | Structure::Ptm, 3) => BCC,
        (Structure::Cna | Structure::Ptm, 4) => ICO,
        (_, v) => return palette(v),
    })
}

/// Which numbering of structure types a column of categories holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Structure {
    /// LAMMPS `cna/atom` (and columns named as structure types: `structure`, `c_struct`).
    Cna,
    /// LAMMPS `ptm/atom`.
    Ptm,
    /// LAMMPS `ackland/atom`.
    Ackland,
}

/// The structure types a column of categories holds, by its name; `None` for any other
/// (a molecule or cluster id).
pub fn structure_kind(column: &str) -> Option<Structure> {
    let c = column.to_ascii_lowercase();
    if c.contains("ackland") {
        Some(Structure::Ackland)
    } else if c.contains("ptm") {
        Some(Structure::Ptm)
    } else if c.contains("cna") || c.contains("struct") {
        Some(Structure::Cna)
    } else {
        None
    }
}

/// A name as a column of categories (`--species-column`) gives it: a whole number in any
/// notation as that number (`1.0` and `1e0` are `1`), anything else as written. The
/// readers name categories this way, so options naming values (`--species-name 1.0=FCC`)
/// are taken the same way.
pub fn category_name(name: &str) -> String {
    whole_number(name.trim()).map_or_else(|| name.to_string(), |v| v.to_string())
}

/// The whole number `text` writes in any notation (`1`, `1.0`, `1e0`, `-0`), below
/// 10^15 in magnitude (where every whole number is a double).
pub fn whole_number(text: &str) -> Option<i64> {
    let v = text.parse::<f64>().ok()?;
    (v.is_finite() && v.fract() == 0.0 && v.abs() < 1e15).then_some(v as i64)
}

/// What a conversion with `--species-column` tells of the species it gave (`species`, as
/// renamed): each rename and radius naming a value none holds (noted, not refused: a
/// script names every structure type), and many species of values that are no whole
/// numbers nor names given (a continuous quantity, each value a species). `one_frame`:
/// one conversion's notes, which list its species; else a batch's, over its frames.
pub fn category_notes(
    column: &str,
    renames: &[(String, String)],
    radii: &[(String, f32)],
    species: &[&str],
    one_frame: bool,
) -> Vec<String> {
    // (A column of molecule or cluster ids gives thousands.)
    let list = match species.len() {
        0..=8 => species.join(", "),
        n => format!("{}, ... ({n} in all)", species[..6].join(", ")),
    };
    let mut notes = Vec::new();
    for (old, new) in renames
        .iter()
        .filter(|(_, new)| !species.contains(&new.as_str()))
    {
        notes.push(match one_frame {
            true => format!(
                "--species-name {old}={new}: no particle has the value {old} in --species-column \
                 {column} here (the species here: {list})"
            ),
            false => format!(
                "--species-name {old}={new}: no frame has the value {old} in --species-column \
                 {column}"
            ),
        });
    }
    // (`*` names every species no other `--radius` names, whichever there are.)
    for (name, radius) in radii
        .iter()
        .filter(|(n, _)| n != ANY_SPECIES && !species.contains(&n.as_str()))
    {
        let renamed = match renames.is_empty() {
            true => "",
            false => ", renamed",
        };
        notes.push(match one_frame {
            true => format!(
                "--radius {name}={radius}: no species {name} here (the species are the values \
                 of --species-column {column}{renamed}: {list})"
            ),
            false => format!(
                "--radius {name}={radius}: no frame has a species {name} (the species are the \
                 values of --species-column {column}{renamed})"
            ),
        });
    }
    // Thousands of whole numbers are ids; values that are not, among that many, are a
    // continuous quantity.
    let named = |n: &str| renames.iter().any(|(_, new)| new == n);
    if species.len() > 64
        && species
            .iter()
            .any(|n| whole_number(n).is_none() && !named(n))
    {
        notes.push(format!(
            "--species-column {column} gave {} species{}, one per distinct value: it takes a \
             column of categories (a structure type, a molecule or cluster id); a continuous \
             quantity goes in --attribute",
            species.len(),
            if one_frame { "" } else { " over the frames" }
        ));
    }
    notes
}

/// Radius of a numeric type or unknown name, in the simulation's length unit.
pub const DEFAULT_RADIUS: f32 = 0.5;

pub(crate) use mdlod_format::meta::{srgb_channel_to_linear, srgb_to_linear};

/// One linear channel in [0, 1] as sRGB.
pub(crate) fn linear_channel_to_srgb(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The element symbol `name` spells, case aside (`li`: `Li`), where it is one.
pub fn element_symbol(name: &str) -> Option<&'static str> {
    ELEMENTS
        .iter()
        .find(|(s, _, _)| s.eq_ignore_ascii_case(name))
        .map(|(s, _, _)| *s)
}

/// The standard radius and colour of an element symbol (case-insensitive), if known.
pub fn element(symbol: &str) -> Option<(f32, [f32; 3])> {
    ELEMENTS
        .iter()
        .find(|(s, _, _)| s.eq_ignore_ascii_case(symbol))
        .map(|(_, r, c)| (*r, srgb_to_linear(*c)))
}

/// How many particles of `species_index` each of `len` species has.
pub fn counts(len: usize, species_index: &[u16]) -> Vec<u64> {
    let mut counts = vec![0u64; len];
    for &s in species_index {
        if let Some(c) = counts.get_mut(usize::from(s)) {
            *c += 1;
        }
    }
    counts
}

/// Folds the sizes of a species as another part of the same frame read them
/// ([`SpeciesName::sized_count`]) into `known`: the mean over both parts' particles and
/// the union of their ranges, so that a frame read in parts (windows, a parallel run's
/// pieces) lists the whole frame's.
pub(crate) fn merge_sizes(known: &mut SpeciesName, part: &SpeciesName) {
    if part.sized_count == 0 {
        return;
    }
    if known.sized_count == 0 {
        known.radius = part.radius;
        known.radius_range = part.radius_range;
        known.sized_count = part.sized_count;
        known.sized_sum = part.sized_sum;
        return;
    }
    known.radius_range = match (known.radius_range, part.radius_range) {
        (Some((lo, hi)), Some((c, d))) => Some((lo.min(c), hi.max(d))),
        (x, y) => x.or(y),
    };
    known.sized_count += part.sized_count;
    known.sized_sum += part.sized_sum;
    // The whole frame's mean, rounded once as a whole read rounds it; a part with a
    // particle of size 0 gave radius 0, which the whole keeps (refused).
    let zero = known.radius_range.is_some_and(|(lo, _)| lo <= 0.0);
    known.radius = Some(if zero {
        0.0
    } else {
        (known.sized_sum / known.sized_count as f64) as f32
    });
}

/// Protein atom names that read as element symbols (PDB and GROMACS names, upper case):
/// the name, the element it reads as, what it names in a protein, and that atom's element.
const ATOM_NAMES_READ_AS_ELEMENTS: [(&str, &str, &str, &str); 6] = [
    ("CA", "calcium", "the alpha carbon", "C"),
    ("CD", "cadmium", "a delta carbon", "C"),
    ("CE", "cerium", "an epsilon carbon", "C"),
    ("NE", "neon", "an epsilon nitrogen", "N"),
    ("HE", "helium", "an epsilon hydrogen", "H"),
    ("HG", "mercury", "a gamma hydrogen", "H"),
];

/// Notes on species whose names are protein atom names that read as elements (`CA` as
/// calcium, drawn large and green), each with the rename that draws the atom it names.
pub fn atom_name_notes<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    names
        .into_iter()
        .filter_map(|n| {
            let (_, element, atom, symbol) =
                ATOM_NAMES_READ_AS_ELEMENTS.iter().find(|(a, ..)| *a == n)?;
            Some(format!(
                "species {n}: read as {element}; in a protein's atom names {n} is {atom}: \
                 --species-name {n}={symbol} draws it as one"
            ))
        })
        .collect()
}

/// A note on species names read as elements beside a majority of names that are none
/// (a Martini system's `W`, `NA` and `CL` beside `NC3`, `PO4`, `GL1`: water and ion
/// beads drawn as tungsten, sodium and chlorine atoms), with the options that make them
/// labels or give them a size. Only names that read so doubtfully are named: symbols
/// written otherwise than the element's case (`NA`, `CL`) and Martini's water `W`;
/// carbon, nitrogen or phosphorus among an all-atom force field's names (`C`, `N`, `P`
/// beside `C13`, `OH2`) are what they say. A species given its own radius (`--radius`)
/// is left out: the user has seen to it. Type numbers count as neither.
pub fn bead_name_note<'a>(species: impl IntoIterator<Item = (&'a str, f32)>) -> Option<String> {
    let species: Vec<(&str, f32)> = species
        .into_iter()
        .filter(|(n, _)| !is_type_number(n))
        .collect();
    let labels = letters_are_labels(species.iter().map(|(n, _)| *n));
    let (elements, others): (Vec<_>, Vec<_>) = species
        .iter()
        .copied()
        .partition(|(n, _)| element_of(n, labels).is_some());
    if elements.is_empty() || others.len() < 2 || others.len() < elements.len() {
        return None;
    }
    let doubtful: Vec<(&str, &str)> = elements
        .iter()
        .filter_map(|&(n, radius)| unsized_element(n, radius).map(|symbol| (n, symbol)))
        // (Lower-case names have a note of their own, [`lower_case_type_note`].)
        .filter(|&(n, symbol)| !lower_case_type(n) && (n != symbol || n == "W"))
        .collect();
    let (shown, symbols, more) = read_as(&doubtful)?;
    let names: Vec<&str> = others.iter().take(4).map(|(n, _)| *n).collect();
    let others_more = if others.len() > 4 { ", ..." } else { "" };
    Some(format!(
        "species {shown}{more}: read as elements ({symbols}{more}) beside names that are \
         none ({}{others_more}): if they are bead or force-field names (Martini's water W, \
         ions NA and CL), --species-name to a name that is no element's makes one a label \
         (a palette colour), and --radius NAME=R gives its size",
        names.join(", "),
    ))
}

/// The element symbol `name` reads as, where its species is drawn at that element's
/// radius (not one of its own: `radius` differs where the user or the input gave one).
fn unsized_element(name: &str, radius: f32) -> Option<&'static str> {
    let (symbol, r, _) = ELEMENTS
        .iter()
        .find(|(s, _, _)| s.eq_ignore_ascii_case(name))?;
    let own_radius = (radius - r).abs() > 1e-6 * r.max(1.0);
    (!own_radius).then_some(*symbol)
}

/// The first four names of `doubtful` (name, element symbol) and what they read as
/// (`ca as Ca, os as Os`), with `, ...` where there are more; `None` for none.
fn read_as(doubtful: &[(&str, &str)]) -> Option<(String, String, &'static str)> {
    if doubtful.is_empty() {
        return None;
    }
    let names: Vec<&str> = doubtful.iter().take(4).map(|(n, _)| *n).collect();
    let symbols: Vec<String> = doubtful
        .iter()
        .take(4)
        .map(|(n, symbol)| format!("{n} as {symbol}"))
        .collect();
    let more = if doubtful.len() > 4 { ", ..." } else { "" };
    Some((names.join(", "), symbols.join(", "), more))
}

/// Whether `name` is written as force fields write atom types and no element symbol is:
/// two letters or more, all lower case (GAFF's `ca`, `os`, `ho`).
fn lower_case_type(name: &str) -> bool {
    name.len() >= 2 && name.bytes().all(|b| b.is_ascii_lowercase())
}

/// A note on species names of two letters or more written all in lower case that read
/// as elements (`ca` as calcium, `os` as osmium, `ho` as holmium): element symbols are
/// never written so, AMBER and GAFF atom types are (`ca` an aromatic carbon, `os` an
/// ether oxygen, `ho` a hydroxyl hydrogen). A species given its own radius is left out.
pub fn lower_case_type_note<'a>(
    species: impl IntoIterator<Item = (&'a str, f32)>,
) -> Option<String> {
    let doubtful: Vec<(&str, &str)> = species
        .into_iter()
        .filter(|(n, _)| lower_case_type(n))
        .filter_map(|(n, radius)| unsized_element(n, radius).map(|symbol| (n, symbol)))
        .collect();
    let (shown, symbols, more) = read_as(&doubtful)?;
    let first = doubtful[0].0;
    Some(format!(
        "species {shown}{more}: read as elements ({symbols}{more}), though element symbols \
         are not written in lower case and force-field atom types are (GAFF's ca is an \
         aromatic carbon, os an ether oxygen, ho a hydroxyl hydrogen): --species-name \
         {first}=C draws one as the element it is, and --radius NAME=R gives its size",
    ))
}

/// Whether a frame's single-letter species names are labels rather than element symbols:
/// some single capital letter among them is no element (HOOMD-blue's `A`, `B`, `C`, a
/// lattice's `A`, `B`), so `B` and `C` beside `A` are no boron and carbon. Names of two or
/// more letters are unaffected, and so are frames whose single letters are all elements
/// (`C`, `H`, `O`). `X` alone does not tell: ASE writes it for its dummy atom (element 0)
/// beside real elements, whose looks one ghost atom must not take away.
pub fn letters_are_labels<'a>(names: impl IntoIterator<Item = &'a str>) -> bool {
    names.into_iter().any(|n| {
        n.len() == 1
            && n.as_bytes()[0].is_ascii_uppercase()
            && n != "X"
            && !SINGLE_LETTER_ELEMENTS.contains(&n)
    })
}

/// Every element whose symbol is one letter (whether or not [`element`] knows its
/// looks): a frame with iodine or yttrium beside carbon names elements, not labels.
const SINGLE_LETTER_ELEMENTS: [&str; 14] = [
    "H", "B", "C", "N", "O", "F", "P", "S", "K", "V", "Y", "I", "W", "U",
];

/// The element a species name stands for, if any: never a single letter where
/// [`letters_are_labels`] (and a type number is no element symbol).
fn element_of(name: &str, letters_are_labels: bool) -> Option<(f32, [f32; 3])> {
    if letters_are_labels && name.len() == 1 {
        return None;
    }
    element(name)
}

/// The looks of every species: the radius the input gives, else the element's or the
/// default, with `overrides` (name, radius) applied last; the colour the input gives,
/// else the element's, else the palette's at the species' own slot (a LAMMPS type's
/// number, so that it keeps its colour in every frame), else at its place in the list.
pub fn species_table(names: &[SpeciesName], overrides: &[(String, f32)]) -> Vec<Species> {
    let labels = letters_are_labels(names.iter().map(|s| s.name.as_str()));
    names
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let colour = match (s.colour, element_of(&s.name, labels)) {
                (Some(c), _) => srgb_to_linear(c),
                (None, Some((_, c))) => c,
                (None, None) => srgb_to_linear(palette_colour(s.palette_slot.unwrap_or(i))),
            };
            let given = radius_override(overrides, &s.name);
            let radius =
                given.unwrap_or_else(|| radius_without_override(&s.name, s.radius, labels));
            // Particles of several sizes: each drawn at its own where the file keeps them
            // (the conversion keeps them exactly where a species has this range).
            let radius_range = s
                .radius_range
                .filter(|&(lo, hi)| {
                    given.is_none() && lo > 0.0 && hi.is_finite() && hi > lo * (1.0 + 1e-3)
                })
                .map(|(lo, hi)| [lo, hi]);
            Species {
                name: s.name.clone(),
                radius,
                colour,
                radius_range,
            }
        })
        .collect()
}

/// Makes the merged species of a frame whose names are not all numbers what a
/// whole-frame reader lists: no species is a numbered type, so none keeps a palette slot
/// of its number (a part's numbers-only list gave them).
pub(crate) fn not_all_numbers(species: &mut [SpeciesName]) {
    for s in species {
        s.numeric_type = false;
        s.palette_slot = None;
    }
}

/// Makes the merged species of a frame of numbers only take palette slots as a
/// whole-frame reader gives them: by number only where every species has one (a part
/// holding a type 0 gave its species none, as the whole frame gives none then).
pub(crate) fn slots_as_whole(species: &mut [SpeciesName]) {
    if species.iter().any(|s| s.palette_slot.is_none()) {
        for s in species {
            s.palette_slot = None;
        }
    }
}

/// The order in which a part of a frame (a window, a piece) adds its species to the
/// frame's list: the order its particles first use them when its reader sorted them
/// numerically, else its list's order. Where the frame's species turn out not to be all
/// numbers, the frame lists them by first appearance, as a whole-frame reader does; where
/// they are, the frame sorts them anyway.
pub(crate) fn merge_order(part: &[SpeciesName], species_index: &[u16]) -> Vec<usize> {
    if part.len() < 2 || !part.iter().all(|s| s.numeric_type) {
        return (0..part.len()).collect();
    }
    let mut order = Vec::with_capacity(part.len());
    let mut seen = vec![false; part.len()];
    for &i in species_index {
        let i = usize::from(i);
        if i < part.len() && !seen[i] {
            seen[i] = true;
            order.push(i);
            if order.len() == part.len() {
                break;
            }
        }
    }
    order.extend((0..part.len()).filter(|&i| !seen[i]));
    order
}

/// The radius a species named `name` gets without an override: `given` (the radius the
/// input gives it) when that is a positive number, else its element's, else the default,
/// as [`species_table`] chooses (`letters_are_labels` of the frame's names).
pub fn radius_without_override(name: &str, given: Option<f32>, letters_are_labels: bool) -> f32 {
    match given.filter(|r| r.is_finite() && *r > 0.0) {
        Some(r) => r,
        None => element_of(name, letters_are_labels).map_or(DEFAULT_RADIUS, |(r, _)| r),
    }
}

/// The species that take [`DEFAULT_RADIUS`] for want of any size: the input gives them
/// none, no element symbol names them and no override sets one (LAMMPS types with no
/// size column and no `--radius`).
pub fn default_radius_species<'a>(
    names: &'a [SpeciesName],
    overrides: &[(String, f32)],
) -> Vec<&'a str> {
    let labels = letters_are_labels(names.iter().map(|s| s.name.as_str()));
    names
        .iter()
        .filter(|s| {
            s.radius.is_none()
                && s.radius_range.is_none()
                && radius_override(overrides, &s.name).is_none()
                && element_of(&s.name, labels).is_none()
        })
        .map(|s| s.name.as_str())
        .collect()
}

/// The first species whose radius from the input is zero, below or not a number and
/// that `overrides` do not give one: such a size cannot be drawn, and must not quietly
/// become the default.
pub fn unusable_radius<'a>(
    names: &'a [SpeciesName],
    overrides: &[(String, f32)],
) -> Option<(&'a str, f32)> {
    names.iter().find_map(|s| {
        let r = s.radius?;
        let bad = !(r.is_finite() && r > 0.0) && radius_override(overrides, &s.name).is_none();
        bad.then_some((s.name.as_str(), r))
    })
}

/// How an input names its species, as far as its first atom tells (see
/// `DumpFile::species_naming`): what an override may call them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SpeciesNaming {
    /// LAMMPS type numbers: a `type` column of numbers and no `element` column (text), or
    /// any binary dump with a `type` column. Only a number can name one. `first` is the
    /// first atom's type.
    TypeNumbers { first: String },
    /// A LAMMPS `element` column: the species are its symbols, never the type numbers
    /// beside them. `first` is the first atom's element, `first_type` its type (when the
    /// dump has a `type` column too).
    ElementColumn {
        first: String,
        first_type: Option<String>,
    },
    /// Names as the input gives them (XYZ species, GSD types, raw sidecar names, MMPLD
    /// lists, LAMMPS type labels, the one species `atom`): any name may occur.
    Given,
}

/// Whether `name` is a number as numeric type names are (see `readers::atoms`).
pub fn is_type_number(name: &str) -> bool {
    name.parse::<i64>().is_ok()
}

impl SpeciesNaming {
    /// When no species of an input named this way can be called `name`: why, and what to
    /// write instead (for an override `name=radius`). `None` when one may be.
    pub fn excludes(&self, name: &str, radius: f32) -> Option<String> {
        match self {
            SpeciesNaming::TypeNumbers { first } if !is_type_number(name) => Some(format!(
                "the input names its species by LAMMPS type number (its `type` column; it has \
                 no `element` column): give the type number instead, e.g. --radius \
                 {first}={radius} for type {first}, or name the type first, e.g. if {name} is \
                 type {first}: --species-name {first}={name} --radius {name}={radius}"
            )),
            SpeciesNaming::ElementColumn { first, first_type } if is_type_number(name) => {
                let example = match first_type {
                    Some(t) if t == name => {
                        format!("--radius {first}={radius} (type {t} is {first})")
                    }
                    _ => format!("e.g. --radius {first}={radius}"),
                };
                Some(format!(
                    "the input names its species by its `element` column, not by type \
                     number: give the element symbol instead, {example}"
                ))
            }
            _ => None,
        }
    }

    /// Why a `--species-name OLD=...` rename cannot name a species of this input (it
    /// names them another way), if it cannot.
    pub fn excludes_rename(&self, old: &str) -> Option<String> {
        match self {
            SpeciesNaming::TypeNumbers { first } if !is_type_number(old) => Some(format!(
                "the input names its species by LAMMPS type number (its `type` column; it has \
                 no `element` column): rename a type number, e.g. --species-name {first}=NAME"
            )),
            SpeciesNaming::ElementColumn { first, .. } if is_type_number(old) => Some(format!(
                "the input names its species by its `element` column, not by type number: \
                 rename an element, e.g. --species-name {first}=NAME"
            )),
            _ => None,
        }
    }
}

/// A radius override given to a species by the name a rename (`--species-name
/// FROM=TO`) takes from it, where no rename gives that name to another: it can name no
/// species of any frame. The error says to give the new name.
pub fn radius_of_a_renamed_species(
    overrides: &[(String, f32)],
    renames: &[(String, String)],
) -> Option<UnknownSpecies> {
    overrides.iter().find_map(|(name, radius)| {
        let taken = renames.iter().any(|(from, to)| from == name && to != name);
        let given = renames.iter().any(|(_, to)| to == name);
        (taken && !given).then(|| UnknownSpecies {
            name: name.clone(),
            radius: *radius,
            known: Vec::new(),
            input: None,
            naming: None,
            renamed: renames.to_vec(),
        })
    })
}

/// A radius override naming none of the input's species.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct UnknownSpecies {
    pub name: String,
    pub radius: f32,
    /// The input's species names.
    pub known: Vec<String>,
    /// The input (its path), when known.
    pub input: Option<String>,
    /// How the input names its species, when known: the message then says what to write
    /// instead of a name that cannot occur.
    pub naming: Option<SpeciesNaming>,
    /// The renames (`--species-name FROM=TO`) applied before the radii: a radius given
    /// to a FROM name is said to take the new name.
    pub renamed: Vec<(String, String)>,
}

impl std::fmt::Display for UnknownSpecies {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(input) = &self.input {
            write!(f, "{input}: ")?;
        }
        if let Some((_, to)) = self.renamed.iter().rfind(|(from, _)| *from == self.name) {
            return write!(
                f,
                "--radius {}={}: --species-name renamed {:?} to {to:?}, and --radius takes the \
                 new name: --radius {to}={}",
                self.name, self.radius, self.name, self.radius
            );
        }
        write!(
            f,
            "--radius {}={}: no species named {:?} (the input's species are named {})",
            self.name,
            self.radius,
            self.name,
            self.known.join(", ")
        )?;
        let why = self
            .naming
            .as_ref()
            .and_then(|n| n.excludes(&self.name, self.radius));
        if let Some(why) = why {
            write!(f, "; {why}")?;
        }
        Ok(())
    }
}

/// Checks that every override names one of `names` (exactly: names are case-sensitive,
/// numeric LAMMPS types are their numbers).
pub fn check_overrides(
    names: &[SpeciesName],
    overrides: &[(String, f32)],
) -> Result<(), Box<UnknownSpecies>> {
    match overrides
        .iter()
        .find(|(n, _)| n != ANY_SPECIES && !names.iter().any(|s| &s.name == n))
    {
        Some((name, radius)) => Err(Box::new(UnknownSpecies {
            name: name.clone(),
            radius: *radius,
            known: names.iter().map(|s| s.name.clone()).collect(),
            input: None,
            naming: None,
            renamed: Vec::new(),
        })),
        None => Ok(()),
    }
}

/// The name an override gives every species no override names by its own
/// (`--radius '*=0.05'`: seven kinds of dark-matter particle at one size).
pub const ANY_SPECIES: &str = "*";

/// The radius `overrides` give species `name` (the last one naming it wins, else the
/// last [`ANY_SPECIES`] one).
pub fn radius_override(overrides: &[(String, f32)], name: &str) -> Option<f32> {
    radius_override_named(overrides, name).map(|(_, r)| r)
}

/// [`radius_override`] with the name the override was given by (`name` or `*`).
pub fn radius_override_named<'a>(
    overrides: &'a [(String, f32)],
    name: &str,
) -> Option<(&'a str, f32)> {
    let by = |want: &str| overrides.iter().rev().find(|(n, _)| n == want);
    by(name)
        .or_else(|| by(ANY_SPECIES))
        .map(|(n, r)| (n.as_str(), *r))
}

/// Parses `FROM=TO` (`--species-name`): a species the input names `FROM` is called `TO`
/// in the file (a LAMMPS type number its element symbol).
pub fn parse_species_name(s: &str) -> Result<(String, String), String> {
    let (from, to) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=NEW_NAME, e.g. 1=O, got {s:?}"))?;
    let (from, to) = (from.trim(), to.trim());
    if from.is_empty() || to.is_empty() {
        return Err(format!("{s:?}: both names must be given, e.g. 1=O"));
    }
    if to
        .chars()
        .any(|c| c.is_whitespace() || c == '=' || c == ',')
    {
        return Err(format!(
            "{s:?}: the new name {to:?} holds a space, `=` or `,` (a species name is one word)"
        ));
    }
    if to.len() > MAX_NAME_LEN {
        return Err(format!(
            "{s:?}: the new name is {} bytes long (at most {MAX_NAME_LEN})",
            to.len()
        ));
    }
    Ok((from.to_string(), to.to_string()))
}

/// The longest name `--species-name` gives a species.
const MAX_NAME_LEN: usize = 64;

/// A `--species-name` naming none of the input's species.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{}--species-name {from}={to}: no species named {from:?} (the input's species are named {})",
    input.as_ref().map(|i| format!("{i}: ")).unwrap_or_default(),
    known.join(", ")
)]
pub struct UnknownRename {
    pub from: String,
    pub to: String,
    /// The input's species names.
    pub known: Vec<String>,
    /// The input (its path), when known.
    pub input: Option<String>,
}

/// Checks that every `--species-name` names one of the input's species `names`.
pub fn check_renames(
    names: &[SpeciesName],
    renames: &[(String, String)],
) -> Result<(), Box<UnknownRename>> {
    match renames
        .iter()
        .find(|(from, _)| !names.iter().any(|s| &s.name == from))
    {
        Some((from, to)) => Err(Box::new(UnknownRename {
            from: from.clone(),
            to: to.clone(),
            known: names.iter().map(|s| s.name.clone()).collect(),
            input: None,
        })),
        None => Ok(()),
    }
}

/// The name `renames` give a species the input names `name` (the last one naming it
/// wins), else its own.
pub fn renamed<'a>(renames: &'a [(String, String)], name: &'a str) -> &'a str {
    renames
        .iter()
        .rev()
        .find(|(from, _)| from == name)
        .map_or(name, |(_, to)| to.as_str())
}

/// The species list after `--species-name` renames (see [`renamed`]), and, where two
/// species end with one name (types 1 and 3 both `O`) and are merged into the first, the
/// map from each input species' index to its index in the new list (`None`: the list
/// keeps its order and length, and indices are unchanged). A renamed species is no
/// longer a numbered type but keeps its palette slot (its colour where the new name is
/// no element), so a renamed list keeps the input's order; a merged species takes the
/// mean of the radii given, weighted by `counts` (the particles of each of `names`;
/// the first radius given where they are not known), and the union of the radius
/// ranges.
pub fn rename_species(
    names: &[SpeciesName],
    counts: &[u64],
    renames: &[(String, String)],
) -> (Vec<SpeciesName>, Option<Vec<u16>>) {
    if renames.is_empty() {
        return (names.to_vec(), None);
    }
    let mut list: Vec<SpeciesName> = Vec::with_capacity(names.len());
    let mut list_counts: Vec<u64> = Vec::with_capacity(names.len());
    let mut map = Vec::with_capacity(names.len());
    for (i, s) in names.iter().enumerate() {
        let name = renamed(renames, &s.name);
        let changed = name != s.name;
        let count = counts.get(i).copied().unwrap_or(0);
        if let Some(k) = list.iter().position(|t| t.name == name) {
            let known = &mut list[k];
            known.numeric_type = false;
            let (a, b) = (list_counts[k], count);
            // Sizes: the union, a species of one size counting as the range of its one
            // radius (a list of one radius merged with one of several), and a species
            // with no particles as none (where counts are known).
            let span = |t: &SpeciesName, n: u64| {
                if counts.is_empty() || n > 0 {
                    t.radius_range.or(t.radius.map(|r| (r, r)))
                } else {
                    None
                }
            };
            let sized = known.radius_range.is_some() || s.radius_range.is_some();
            known.radius_range = match (span(known, a), span(s, b)) {
                (Some((p, q)), Some((c, d))) if sized => Some((p.min(c), q.max(d))),
                (p, q) if sized => p.or(q),
                _ => None,
            };
            // The mean over both species' particles; a species with no particles gives
            // none, and a radius of 0 or below of one with particles stays, to be
            // refused naming the species.
            known.radius = match (known.radius, s.radius) {
                (Some(_), Some(y)) if a == 0 && b > 0 => Some(y),
                (Some(x), Some(_)) if b == 0 && a > 0 => Some(x),
                (Some(x), Some(y)) if x > 0.0 && y > 0.0 && a > 0 && b > 0 => Some(
                    ((f64::from(x) * a as f64 + f64::from(y) * b as f64) / (a + b) as f64) as f32,
                ),
                (Some(x), Some(y)) if y <= 0.0 && x > 0.0 => Some(y),
                (x, y) => x.or(y),
            };
            list_counts[k] += b;
            known.colour = known.colour.or(s.colour);
            map.push(k as u16);
            continue;
        }
        let mut t = s.clone();
        if changed {
            t.name = name.to_string();
            t.numeric_type = false;
        }
        list_counts.push(count);
        map.push(list.len() as u16);
        list.push(t);
    }
    let identity = list.len() == names.len();
    (list, (!identity).then_some(map))
}

/// Parses `NAME=RADIUS`.
pub fn parse_radius_override(s: &str) -> Result<(String, f32), String> {
    let (name, r) = s
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=RADIUS, got {s:?}"))?;
    if name.trim().is_empty() {
        return Err(format!(
            "{s:?}: expected NAME=RADIUS, a species' name before `=`"
        ));
    }
    let r: f32 = r
        .trim()
        .parse()
        .map_err(|_| format!("radius {r:?} in {s:?} is not a number"))?;
    if !(r.is_finite() && r > 0.0) {
        return Err(format!("radius in {s:?} must be positive"));
    }
    Ok((name.trim().to_string(), r))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--radius '*=R'` gives every species of a `--species-column` its radius, so no
    /// note says it names none here; a name that is none is noted, said renamed only
    /// where `--species-name` renamed some.
    #[test]
    fn category_notes_pass_over_the_star_and_say_renamed_only_when_so() {
        let radii = vec![("*".to_string(), 1.3f32), ("hcp".to_string(), 1.2f32)];
        let notes = category_notes("c_cna", &[], &radii, &["1", "2", "5"], true);
        assert_eq!(
            notes,
            [
                "--radius hcp=1.2: no species hcp here (the species are the values of \
              --species-column c_cna: 1, 2, 5)"
            ]
        );
        let renames = vec![("2".to_string(), "hcp".to_string())];
        let notes = category_notes("c_cna", &renames, &radii, &["1", "hcp", "5"], true);
        assert!(notes.is_empty(), "{notes:?}");
    }

    #[test]
    fn protein_atom_names_read_as_elements_are_noted() {
        let notes = super::atom_name_notes(["CA", "Ca", "CB", "HG", "N"]);
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(
            notes[0].starts_with("species CA: read as calcium; in a protein's atom names CA is the alpha carbon: --species-name CA=C"),
            "{notes:?}"
        );
        assert!(notes[1].contains("--species-name HG=H"), "{notes:?}");
        // Elements of the new rows.
        assert!(super::element("Br").is_some() && super::element("I").is_some());
    }

    #[test]
    fn elements_numeric_types_and_overrides() {
        let names = vec![
            SpeciesName {
                name: "Cu".into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            },
            SpeciesName {
                name: "2".into(),
                numeric_type: true,
                radius: None,
                ..Default::default()
            },
            SpeciesName {
                name: "Xx".into(),
                numeric_type: false,
                radius: None,
                ..Default::default()
            },
        ];
        let t = species_table(&names, &[("2".into(), 0.9)]);
        assert_eq!(t[0].radius, 1.28);
        assert_eq!(t[1].radius, 0.9);
        assert_eq!(t[2].radius, DEFAULT_RADIUS);
        assert_ne!(t[1].colour, t[2].colour);
        assert!(parse_radius_override("Cu=1.3").is_ok());
        assert!(parse_radius_override("Cu").is_err());
        assert!(parse_radius_override("Cu=-1").is_err());
    }

    /// Element symbols among mostly other names (a Martini bilayer's W, NA and CL
    /// beside NC3, PO4, GL1, C1A) are noted; frames of elements, of type numbers, or of
    /// elements with a site name or two (water models' Ow, Hw) are not.
    #[test]
    fn element_names_among_bead_names_are_noted() {
        let at = |names: &[&'static str]| -> Vec<(&'static str, f32)> {
            names
                .iter()
                .map(|n| (*n, element(n).map_or(DEFAULT_RADIUS, |(r, _)| r)))
                .collect()
        };
        let martini = at(&["NC3", "PO4", "GL1", "C1A", "W", "NA", "CL"]);
        let note = bead_name_note(martini.clone()).expect("a note");
        assert!(
            note.starts_with(
                "species W, NA, CL: read as elements (W as W, NA as Na, CL as Cl) beside names \
                 that are none (NC3, PO4, GL1, C1A)"
            ),
            "{note}"
        );
        // Given their own radii: seen to.
        let sized: Vec<(&str, f32)> = martini
            .iter()
            .map(|&(n, r)| (n, if element(n).is_some() { 2.35 } else { r }))
            .collect();
        assert_eq!(bead_name_note(sized), None);
        // An all-atom force field's C, N, P are what they say; its NA is named.
        assert_eq!(
            bead_name_note(at(&["N", "C", "P", "C13", "OH2", "C12"])),
            None
        );
        let charmm = bead_name_note(at(&["N", "C", "P", "NA", "C13", "OH2", "C12", "HA"]));
        assert!(charmm.is_some_and(|n| n.starts_with("species NA: read as elements (NA as Na)")));
        assert_eq!(bead_name_note(at(&["Cu", "Ag", "Ni"])), None);
        assert_eq!(bead_name_note(at(&["1", "2", "3"])), None);
        assert_eq!(bead_name_note(at(&["C", "H", "O", "Ow", "Hw"])), None);
        assert_eq!(bead_name_note(at(&["Cu", "vacancy"])), None);
        assert_eq!(bead_name_note(at(&["A", "B"])), None);
        // GAFF's lower-case atom types that read as elements are noted, all of them,
        // whatever the others; element symbols and lower-case names of no element are not.
        let gaff = at(&[
            "c3", "hc", "ca", "ha", "o", "n", "h", "c", "os", "oh", "ho", "cl",
        ]);
        let note = lower_case_type_note(gaff.clone()).expect("a note");
        assert!(
            note.starts_with(
                "species ca, os, ho, cl: read as elements (ca as Ca, os as Os, ho as Ho, cl as \
                 Cl)"
            ) && note.contains("--species-name ca=C"),
            "{note}"
        );
        assert_eq!(bead_name_note(gaff), None);
        assert_eq!(
            lower_case_type_note(at(&["Ca", "Os", "CA", "c3", "h"])),
            None
        );
    }

    /// HOOMD-blue names types `A`, `B`, `C`: beside `A` (no element), `B` and `C` are
    /// labels in palette colours with the default radius, not boron and carbon; `C`, `H`,
    /// `O` alone are elements, and `Cu` stays copper beside `A`.
    #[test]
    fn single_letters_beside_a_letter_that_is_no_element_are_labels() {
        let named = |names: &[&str]| -> Vec<SpeciesName> {
            names
                .iter()
                .map(|n| SpeciesName {
                    name: (*n).into(),
                    ..Default::default()
                })
                .collect()
        };
        let palette = |i: usize| palette_colour_linear(i);
        let t = species_table(&named(&["A", "B", "C", "Cu"]), &[]);
        for (i, s) in t.iter().enumerate().take(3) {
            assert_eq!(
                (s.radius, s.colour),
                (DEFAULT_RADIUS, palette(i)),
                "{}",
                s.name
            );
        }
        assert_eq!((t[3].radius, t[3].colour), element("Cu").unwrap());
        let t = species_table(&named(&["C", "H", "O"]), &[]);
        for s in &t {
            assert_eq!(
                (s.radius, s.colour),
                element(&s.name).unwrap(),
                "{}",
                s.name
            );
        }
        assert!(letters_are_labels(["A", "B"]));
        // Many types: no two of the first 64 slots share a colour.
        let colours: std::collections::BTreeSet<[u8; 3]> = (0..64).map(palette_colour).collect();
        assert_eq!(colours.len(), 64);
        assert_eq!(palette_colour(0), [230, 102, 51]);
        assert!(!letters_are_labels(["B", "C", "Cu"]));
        // Iodine and yttrium are elements too (MAPbI3: Pb I C N H).
        assert!(!letters_are_labels(["Pb", "I", "C", "N", "H"]));
        assert!(!letters_are_labels(["Y", "O"]));
        // ASE's dummy atom beside methanol's elements: still elements; with `A`, labels.
        assert!(!letters_are_labels(["C", "O", "H", "X"]));
        assert!(letters_are_labels(["A", "B", "X"]));
        // Every element of the periodic table has its looks (ASE writes any of them).
        for symbol in [
            "Tc", "Pr", "Pm", "Sm", "Eu", "Tb", "Dy", "Ho", "Er", "Tm", "Yb", "Lu", "Po", "At",
            "Rn", "Fr", "Ra", "Ac", "Th", "Pa", "Np", "Pu", "Am", "Cm", "Og",
        ] {
            assert!(element(symbol).is_some(), "{symbol}");
        }
        assert_eq!(ELEMENTS.len(), 118);
        assert_eq!(radius_without_override("B", None, true), DEFAULT_RADIUS);
        assert_eq!(
            radius_without_override("B", None, false),
            element("B").unwrap().0
        );
    }

    /// Particles of several sizes keep their range in the file (for `info`), unless
    /// `--radius` gives the species one, or the sizes differ by rounding only.
    #[test]
    fn a_polydisperse_species_keeps_its_radius_range() {
        let named = |name: &str, range| SpeciesName {
            name: name.into(),
            radius: Some(0.5),
            radius_range: Some(range),
            ..Default::default()
        };
        let names = [named("A", (0.3, 0.7)), named("B", (0.5, 0.50001))];
        let table = species_table(&names, &[]);
        assert_eq!(table[0].radius_range, Some([0.3, 0.7]));
        assert_eq!(table[1].radius_range, None);
        let table = species_table(&names, &[("A".into(), 0.6)]);
        assert_eq!((table[0].radius, table[0].radius_range), (0.6, None));
    }

    #[test]
    fn an_override_naming_no_species_is_an_error_listing_them() {
        let names = [("1", true), ("2", true)].map(|(n, numeric)| SpeciesName {
            name: n.into(),
            numeric_type: numeric,
            radius: None,
            ..Default::default()
        });
        check_overrides(&names, &[("2".into(), 0.9)]).unwrap();
        // `*` names every species no override names by its own.
        let any = [("*".to_string(), 0.3), ("2".to_string(), 0.9)];
        check_overrides(&names, &any).unwrap();
        assert_eq!(radius_override(&any, "1"), Some(0.3));
        assert_eq!(radius_override(&any, "2"), Some(0.9));
        assert_eq!(radius_override_named(&any, "1"), Some(("*", 0.3)));
        assert_eq!(radius_override(&any[1..], "1"), None);
        let e = check_overrides(&names, &[("2".into(), 0.9), ("Cu".into(), 1.28)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"Cu\"") && e.contains("the input's species are named 1, 2"),
            "{e}"
        );
        // How the input names its species says what to write instead of a name that
        // cannot occur.
        let e = UnknownSpecies {
            naming: Some(SpeciesNaming::TypeNumbers { first: "1".into() }),
            input: Some("a.dump".into()),
            ..*check_overrides(&names, &[("Cu".into(), 1.28)]).unwrap_err()
        }
        .to_string();
        assert_eq!(
            e,
            "a.dump: --radius Cu=1.28: no species named \"Cu\" (the input's species are named \
             1, 2); the input names its species by LAMMPS type number (its `type` column; it \
             has no `element` column): give the type number instead, e.g. --radius 1=1.28 for \
             type 1, or name the type first, e.g. if Cu is type 1: --species-name 1=Cu \
             --radius Cu=1.28"
        );
        let element = SpeciesNaming::ElementColumn {
            first: "Cu".into(),
            first_type: Some("1".into()),
        };
        assert!(element.excludes("Cu", 1.0).is_none());
        assert!(element
            .excludes("2", 1.0)
            .unwrap()
            .contains("e.g. --radius Cu=1"));
        assert!(element
            .excludes("1", 1.3)
            .unwrap()
            .contains("`element` column, not by type number: give the element symbol instead, --radius Cu=1.3 (type 1 is Cu)"));
        let numbers = SpeciesNaming::TypeNumbers { first: "2".into() };
        assert!(numbers.excludes("7", 1.0).is_none());
        assert!(SpeciesNaming::Given.excludes("Cu", 1.0).is_none());
        assert!(SpeciesNaming::Given.excludes("1", 1.0).is_none());
        // Names are exact: `cu` is not `Cu`.
        let cu = [SpeciesName {
            name: "Cu".into(),
            numeric_type: false,
            radius: None,
            ..Default::default()
        }];
        assert!(check_overrides(&cu, &[("cu".into(), 1.0)]).is_err());
    }

    fn numbered(types: &[&str]) -> Vec<SpeciesName> {
        types
            .iter()
            .map(|t| SpeciesName {
                name: (*t).into(),
                numeric_type: true,
                palette_slot: Some(t.parse::<usize>().unwrap() - 1),
                ..Default::default()
            })
            .collect()
    }

    #[test]
    fn renamed_types_take_their_elements_looks_and_keep_the_order() {
        let names = numbered(&["1", "2", "3"]);
        let renames = vec![("1".to_string(), "O".to_string()), ("2".into(), "H".into())];
        let (list, map) = rename_species(&names, &[], &renames);
        assert!(map.is_none(), "nothing merged: indices unchanged");
        let got: Vec<_> = list.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(got, ["O", "H", "3"]);
        assert!(!list[0].numeric_type && !list[1].numeric_type && list[2].numeric_type);
        let table = species_table(&list, &[]);
        let (o_radius, o_colour) = element("O").unwrap();
        assert_eq!((table[0].radius, table[0].colour), (o_radius, o_colour));
        assert_eq!(table[1].radius, element("H").unwrap().0);
        // The unrenamed type keeps the palette colour of its number.
        assert_eq!(table[2].colour, palette_colour_linear(2));
        assert_eq!(table[2].radius, DEFAULT_RADIUS);
        // Overrides name the new names.
        let table = species_table(&list, &[("O".into(), 1.7)]);
        assert_eq!(table[0].radius, 1.7);
        // No renames: the list as it was.
        assert_eq!(rename_species(&names, &[], &[]), (names.clone(), None));
    }

    #[test]
    fn species_merged_by_a_rename_take_the_mean_radius_of_all_their_particles() {
        let mut names = numbered(&["1", "2", "3"]);
        names[0].radius = Some(0.5);
        names[1].radius = Some(2.0);
        names[2].radius = Some(1.0);
        let renames = [("1".to_string(), "A".to_string()), ("2".into(), "A".into())];
        // 3 particles of radius 0.5 and 1 of radius 2: (1.5 + 2) / 4.
        let (list, _) = rename_species(&names, &[3, 1, 7], &renames);
        assert_eq!(list[0].radius, Some(0.875));
        assert_eq!(list[1].radius, Some(1.0));
        // Counts not known: the first radius given.
        let (list, _) = rename_species(&names, &[], &renames);
        assert_eq!(list[0].radius, Some(0.5));
        // A radius of 0 stays, to be refused.
        names[1].radius = Some(0.0);
        let (list, _) = rename_species(&names, &[3, 1, 7], &renames);
        assert_eq!(list[0].radius, Some(0.0));
        // A species with no particles gives the merged one neither its radius nor a 0.
        let (list, _) = rename_species(&names, &[0, 1, 7], &renames);
        assert_eq!(list[0].radius, Some(0.0));
        names[1].radius = Some(2.0);
        let (list, _) = rename_species(&names, &[0, 1, 7], &renames);
        assert_eq!((list[0].radius, list[0].radius_range), (Some(2.0), None));
        names[0].radius = Some(0.0);
        let (list, _) = rename_species(&names, &[0, 1, 7], &renames);
        assert_eq!(list[0].radius, Some(2.0));
        // A species of several sizes merged with one of one size: the union holds both.
        names[0].radius = Some(0.3);
        names[0].radius_range = Some((0.1, 0.5));
        let (list, _) = rename_species(&names, &[3, 1, 7], &renames);
        assert_eq!(list[0].radius_range, Some((0.1, 2.0)));
    }

    #[test]
    fn two_types_given_one_name_are_merged_into_the_first() {
        let mut names = numbered(&["1", "2", "3", "4"]);
        names[2].radius = Some(0.7);
        names[1].radius_range = Some((0.5, 0.6));
        names[3].radius_range = Some((0.4, 0.55));
        let renames = vec![
            ("1".to_string(), "O".to_string()),
            ("3".into(), "O".into()),
            ("2".into(), "X".into()),
            ("4".into(), "X".into()),
        ];
        let (list, map) = rename_species(&names, &[], &renames);
        let got: Vec<_> = list.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(got, ["O", "X"]);
        assert_eq!(map, Some(vec![0, 1, 0, 1]));
        assert_eq!(list[0].radius, Some(0.7), "the radius type 3 gives");
        assert_eq!(list[1].radius_range, Some((0.4, 0.6)));
        // A type renamed to another's number joins it.
        let (list, map) = rename_species(&numbered(&["1", "2"]), &[], &[("2".into(), "1".into())]);
        assert_eq!(list.len(), 1);
        assert!(!list[0].numeric_type);
        assert_eq!(map, Some(vec![0, 0]));
        // The last rename of a name wins.
        assert_eq!(
            renamed(&[("1".into(), "N".into()), ("1".into(), "O".into())], "1"),
            "O"
        );
    }

    #[test]
    fn species_names_are_parsed_and_checked() {
        assert_eq!(
            parse_species_name(" 1 = O ").unwrap(),
            ("1".to_string(), "O".to_string())
        );
        for bad in ["1", "=O", "1=", "1=O H", "1=a=b", "1=O,H"] {
            assert!(parse_species_name(bad).is_err(), "{bad}");
        }
        assert!(parse_species_name(&format!("1={}", "x".repeat(65))).is_err());
        let names = numbered(&["1", "2"]);
        assert!(check_renames(&names, &[("2".into(), "H".into())]).is_ok());
        let e = UnknownRename {
            input: Some("water.dump".into()),
            ..*check_renames(&names, &[("OW".into(), "O".into())]).unwrap_err()
        };
        assert_eq!(
            e.to_string(),
            "water.dump: --species-name OW=O: no species named \"OW\" (the input's species \
             are named 1, 2)"
        );
    }
}
