//! How particles look beyond the file's species table: per-species colours, radii and
//! visibility, a global radius scale, and colouring by the scalar attribute through a
//! colour map.
//!
//! How it works: the style is applied when a cut is packed for the GPU (see
//! [`crate::passes::sphere_raycast::pack_styled`]), so no shader changes and no
//! particle data is rewritten. Particles take their species' styled colour and radius,
//! or, with a colour map, the map's colour of their own attribute value (they are then
//! packed like cluster records: radius and colour per point). Clusters take the map's
//! colour of their area-weighted mean attribute (both mapped to [0, 1] by
//! [`AttributeScale`]), and their coverage radius times the radius scale; without a map
//! their stored mixture of species colours goes through the affine map that takes every
//! species' colour to its styled one ([`PointStyle::cluster_recolour`]: exact for up to
//! four species of affinely independent colours, a least-squares fit beyond). Hiding is exact at
//! the particle level only: a cluster drawn in place of a hidden species' particles
//! still shows them. Styles that change sizes turn occlusion culling off (it assumes the
//! file's radii); hiding does not (the traversal occludes with what it draws only).

use mdlod_format::reader::in_species_set;
use serde::{Deserialize, Serialize};

/// One species' look, by its name in the file (each `None` keeps the file's value).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SpeciesStyle {
    pub name: String,
    /// Linear RGB albedo.
    pub colour: Option<[f32; 3]>,
    pub radius: Option<f32>,
    pub hidden: bool,
}

/// Why [`default_range`] maps an attribute over another range than its values' own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RangeChoice {
    /// Splats lit by their values: from 0, so that each splat's light is its value
    /// times its disk's area.
    FromZero,
    /// A log scale over values reaching 0 or below: from the smallest value above 0.
    LogFloor,
    /// A diverging map over values of both signs: centred on 0, the map's white.
    Centred,
    /// Some particles hidden: the shown particles' values only.
    Shown,
}

impl RangeChoice {
    /// Why, in words for a summary.
    pub fn why(self) -> &'static str {
        match self {
            RangeChoice::FromZero => {
                "from 0, so that each splat's light is its value times its disk's area (a \
                 particle at the smallest value still shines)"
            }
            RangeChoice::LogFloor => {
                "from the smallest value above 0: values at or below it take the scale's \
                 start"
            }
            RangeChoice::Centred => "centred on 0, the map's white",
            RangeChoice::Shown => {
                "over the values of the particles the map colours, those hidden, cut away or \
                 in colours of their own left out"
            }
        }
    }
}

/// The range an attribute whose values span `[min, max]` is mapped over where none is
/// given and its own would mislead, with why; `None` where its own serves. Splats lit
/// by the values (`light`) start at 0, so that light is proportional to value (their own
/// range would give the smallest value no light, and a mass of 2 against one of 6 a third
/// of the light it carries); then, for colours by the attribute (`mapped`), a
/// log scale (`log`) starts at the smallest value above 0 (`floor`, at least 10⁻⁸ of the
/// top), and a diverging `map` is centred on 0.
pub fn default_range(
    [min, max]: [f32; 2],
    light: bool,
    mapped: bool,
    log: bool,
    map: Option<ColourMap>,
    floor: Option<f32>,
) -> Option<([f32; 2], RangeChoice)> {
    if light && min > 0.0 && max > min {
        return Some(([0.0, max], RangeChoice::FromZero));
    }
    if !mapped {
        return None;
    }
    if log {
        let floor = floor?.max(max * 1e-8);
        return (min <= 0.0 && max > floor).then_some(([floor, max], RangeChoice::LogFloor));
    }
    Some((map?.centred_range([min, max])?, RangeChoice::Centred))
}

/// The look (colour, radius) each species name keeps throughout a trajectory whose
/// frames were converted apart. A frame's file fixes its species' looks from that frame
/// alone: palette colours by place in its list (GSD type lists in another order, a type
/// present only later), single letters as elements or labels by the frame's names. A
/// name takes its look in the frame holding the most species (the earliest of those),
/// where the names are judged among the most others; names that frame lacks, in their
/// first frame.
///
/// Two names no frame holds together may have taken the same palette slot (a solvent
/// that evaporates, then ions deposited in its place, each third in its frames' lists):
/// the later name takes the first palette colour no look has, so that a movie and its
/// legend tell them apart. Colours a frame gives two of its own names are left alone.
pub fn trajectory_looks(
    frames: &[&[mdlod_format::meta::Species]],
) -> Vec<mdlod_format::meta::Species> {
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(frames[i].len()), i));
    let mut looks: Vec<mdlod_format::meta::Species> = Vec::new();
    for i in order {
        for s in frames[i] {
            if !looks.iter().any(|l| l.name == s.name) {
                looks.push(s.clone());
            }
        }
    }
    let same = |a: [f32; 3], b: [f32; 3]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= 1e-4);
    let together = |a: &str, b: &str| {
        frames
            .iter()
            .any(|f| f.iter().any(|s| s.name == a) && f.iter().any(|s| s.name == b))
    };
    // (Past this many slots a colour is not the palette's: the slots a list of names
    // that long takes, and ten more.)
    let slots = looks.len() + 10;
    let palette = |c: [f32; 3]| palette_slot(c, slots).is_some();
    for j in 1..looks.len() {
        let clash = looks[..j]
            .iter()
            .any(|l| same(l.colour, looks[j].colour) && !together(&l.name, &looks[j].name));
        if !clash || !palette(looks[j].colour) {
            continue;
        }
        let free = (0..)
            .map(mdlod_format::meta::palette_colour_linear)
            .find(|&c| !looks.iter().any(|l| same(l.colour, c)));
        if let Some(c) = free {
            looks[j].colour = c;
        }
    }
    looks
}

/// The species styles that draw a frame's species (`own`) with the trajectory's looks
/// ([`trajectory_looks`]), after the user's `styles` (which win: a colour or radius
/// given there is kept, a hidden species stays hidden). A radius is the frame's data
/// (a GSD frame's diameters, an MMPLD list's radius: particles that grow or shrink over
/// a run) and is kept, unless the frame read the name otherwise, as its other colour
/// says (`B` as boron where no `A` made it a label); radii within 1 % of the look's are
/// left alone then too (a per-frame mean of polydisperse diameters).
pub fn keep_looks(
    own: &[mdlod_format::meta::Species],
    looks: &[mdlod_format::meta::Species],
    styles: &[SpeciesStyle],
) -> Vec<SpeciesStyle> {
    let mut out: Vec<SpeciesStyle> = styles
        .iter()
        .filter(|st| own.iter().any(|s| s.name == st.name))
        .cloned()
        .collect();
    for s in own {
        let Some(look) = looks.iter().find(|l| l.name == s.name) else {
            continue;
        };
        // A hidden species has no look to keep.
        if styles.iter().any(|st| st.name == s.name && st.hidden) {
            continue;
        }
        let colour = (look
            .colour
            .iter()
            .zip(&s.colour)
            .any(|(a, b)| (a - b).abs() > 1e-4))
        .then_some(look.colour);
        let radius = (colour.is_some() && (look.radius - s.radius).abs() > 0.01 * look.radius)
            .then_some(look.radius);
        if colour.is_none() && radius.is_none() {
            continue;
        }
        match out.iter_mut().rfind(|st| st.name == s.name) {
            Some(st) => {
                st.colour = st.colour.or(colour);
                st.radius = st.radius.or(radius);
            }
            None => out.push(SpeciesStyle {
                name: s.name.clone(),
                colour,
                radius,
                hidden: false,
            }),
        }
    }
    out
}

/// The species styles one frame of a trajectory is drawn with: [`keep_looks`], and under
/// a colour map only the colours the user named (a species' colour there pins it out of
/// the map, and the looks' colours would pin the species whose palette colour moved in
/// this frame). `mdlod render DIR` and the viewer's timesteps alike. A look's palette
/// colour takes `palette`'s place for it, as the species' own colour would.
pub fn frame_styles(
    own: &[mdlod_format::meta::Species],
    looks: &[mdlod_format::meta::Species],
    styles: &[SpeciesStyle],
    colour_map: bool,
    palette: Palette,
) -> Vec<SpeciesStyle> {
    let mut out = keep_looks(own, looks, styles);
    for st in &mut out {
        let named = styles
            .iter()
            .any(|u| u.name == st.name && u.colour.is_some());
        if !named {
            st.colour = st.colour.map(|c| palette.colour(c));
        }
    }
    if colour_map {
        for st in &mut out {
            let named = styles
                .iter()
                .any(|u| u.name == st.name && u.colour.is_some());
            if !named {
                st.colour = None;
            }
        }
    }
    out
}

/// Colour maps for the scalar attribute (perceptually ordered, from low to high).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColourMap {
    #[default]
    Viridis,
    Magma,
    /// Blue to yellow, its lightness rising evenly, seen alike with the common colour
    /// vision deficiencies (Nuñez et al. 2018).
    Cividis,
    /// Blue through white to red, for signed quantities.
    CoolWarm,
    Grey,
}

impl ColourMap {
    pub const ALL: [ColourMap; 5] = [
        ColourMap::Viridis,
        ColourMap::Magma,
        ColourMap::Cividis,
        ColourMap::CoolWarm,
        ColourMap::Grey,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ColourMap::Viridis => "viridis",
            ColourMap::Magma => "magma",
            ColourMap::Cividis => "cividis",
            ColourMap::CoolWarm => "cool-warm",
            ColourMap::Grey => "grey",
        }
    }

    pub fn from_name(name: &str) -> Option<ColourMap> {
        ColourMap::ALL.into_iter().find(|m| m.name() == name)
    }

    /// True for maps whose middle colour means zero (cool-warm: blue below, red above).
    pub fn is_diverging(self) -> bool {
        self == ColourMap::CoolWarm
    }

    /// The range a diverging map shows `[lo, hi]` over: centred on 0 where the values
    /// take both signs (`[-m, m]`, `m` the larger magnitude), so that white is 0 and a
    /// colour's depth means the same magnitude on both sides; `None` for other maps and
    /// for values of one sign.
    pub fn centred_range(self, [lo, hi]: [f32; 2]) -> Option<[f32; 2]> {
        let m = lo.abs().max(hi.abs());
        (self.is_diverging() && lo < 0.0 && hi > 0.0 && m.is_finite()).then_some([-m, m])
    }

    /// sRGB control points, evenly spaced over [0, 1].
    fn stops(self) -> &'static [[f32; 3]] {
        match self {
            // Matplotlib's viridis and magma (van der Walt and Smith, CC0), sampled at 33
            // points: within 3 levels of theirs everywhere (11 stops were up to 13 off).
            ColourMap::Viridis => &[
                [0.267, 0.005, 0.329],
                [0.277, 0.050, 0.376],
                [0.282, 0.095, 0.417],
                [0.283, 0.136, 0.453],
                [0.279, 0.175, 0.483],
                [0.271, 0.214, 0.507],
                [0.259, 0.252, 0.525],
                [0.245, 0.288, 0.537],
                [0.230, 0.322, 0.546],
                [0.214, 0.356, 0.551],
                [0.199, 0.388, 0.555],
                [0.186, 0.419, 0.557],
                [0.173, 0.449, 0.558],
                [0.161, 0.479, 0.558],
                [0.149, 0.508, 0.557],
                [0.138, 0.537, 0.555],
                [0.128, 0.567, 0.551],
                [0.121, 0.596, 0.544],
                [0.121, 0.626, 0.533],
                [0.132, 0.655, 0.520],
                [0.158, 0.684, 0.502],
                [0.197, 0.712, 0.479],
                [0.246, 0.739, 0.452],
                [0.304, 0.765, 0.420],
                [0.369, 0.789, 0.383],
                [0.440, 0.811, 0.341],
                [0.516, 0.831, 0.294],
                [0.596, 0.849, 0.243],
                [0.678, 0.864, 0.190],
                [0.762, 0.876, 0.137],
                [0.846, 0.887, 0.100],
                [0.926, 0.897, 0.104],
                [0.993, 0.906, 0.144],
            ],
            ColourMap::Magma => &[
                [0.001, 0.000, 0.014],
                [0.014, 0.012, 0.069],
                [0.040, 0.031, 0.134],
                [0.074, 0.052, 0.203],
                [0.113, 0.065, 0.277],
                [0.159, 0.068, 0.353],
                [0.212, 0.062, 0.419],
                [0.265, 0.060, 0.462],
                [0.317, 0.072, 0.485],
                [0.366, 0.090, 0.498],
                [0.415, 0.110, 0.505],
                [0.464, 0.130, 0.508],
                [0.513, 0.148, 0.508],
                [0.563, 0.165, 0.505],
                [0.614, 0.182, 0.499],
                [0.665, 0.198, 0.489],
                [0.716, 0.215, 0.475],
                [0.767, 0.234, 0.458],
                [0.817, 0.256, 0.436],
                [0.863, 0.284, 0.412],
                [0.904, 0.320, 0.388],
                [0.937, 0.365, 0.369],
                [0.961, 0.418, 0.360],
                [0.977, 0.476, 0.364],
                [0.987, 0.536, 0.382],
                [0.993, 0.595, 0.410],
                [0.996, 0.654, 0.446],
                [0.997, 0.712, 0.488],
                [0.997, 0.770, 0.535],
                [0.995, 0.827, 0.586],
                [0.992, 0.884, 0.640],
                [0.989, 0.941, 0.698],
                [0.987, 0.991, 0.750],
            ],
            // Matplotlib's cividis (CC0), sampled at 65 points: within 3 levels of its
            // 256 everywhere (33 were up to 6 off, at its bends near the ends).
            ColourMap::Cividis => &[
                [0.000, 0.135, 0.305],
                [0.000, 0.147, 0.330],
                [0.000, 0.158, 0.358],
                [0.000, 0.168, 0.386],
                [0.000, 0.179, 0.415],
                [0.000, 0.189, 0.440],
                [0.018, 0.199, 0.441],
                [0.069, 0.209, 0.439],
                [0.103, 0.220, 0.436],
                [0.131, 0.231, 0.433],
                [0.154, 0.242, 0.430],
                [0.175, 0.253, 0.428],
                [0.195, 0.264, 0.426],
                [0.213, 0.275, 0.424],
                [0.231, 0.286, 0.423],
                [0.248, 0.297, 0.423],
                [0.264, 0.308, 0.423],
                [0.279, 0.319, 0.423],
                [0.295, 0.330, 0.424],
                [0.310, 0.340, 0.425],
                [0.324, 0.351, 0.426],
                [0.339, 0.362, 0.428],
                [0.353, 0.373, 0.430],
                [0.367, 0.384, 0.433],
                [0.381, 0.395, 0.436],
                [0.395, 0.406, 0.439],
                [0.408, 0.417, 0.443],
                [0.422, 0.429, 0.447],
                [0.435, 0.440, 0.451],
                [0.448, 0.451, 0.456],
                [0.462, 0.462, 0.462],
                [0.475, 0.474, 0.468],
                [0.489, 0.485, 0.471],
                [0.500, 0.494, 0.472],
                [0.514, 0.506, 0.473],
                [0.529, 0.517, 0.473],
                [0.544, 0.529, 0.472],
                [0.559, 0.541, 0.471],
                [0.574, 0.553, 0.469],
                [0.590, 0.565, 0.467],
                [0.605, 0.577, 0.464],
                [0.621, 0.589, 0.461],
                [0.636, 0.601, 0.458],
                [0.652, 0.614, 0.454],
                [0.668, 0.626, 0.449],
                [0.684, 0.639, 0.444],
                [0.700, 0.652, 0.439],
                [0.716, 0.664, 0.432],
                [0.732, 0.677, 0.426],
                [0.749, 0.690, 0.418],
                [0.765, 0.704, 0.411],
                [0.782, 0.717, 0.402],
                [0.798, 0.731, 0.393],
                [0.815, 0.744, 0.383],
                [0.832, 0.758, 0.372],
                [0.849, 0.772, 0.360],
                [0.866, 0.786, 0.347],
                [0.884, 0.800, 0.333],
                [0.901, 0.815, 0.317],
                [0.919, 0.829, 0.300],
                [0.937, 0.844, 0.281],
                [0.955, 0.859, 0.259],
                [0.973, 0.874, 0.235],
                [0.992, 0.888, 0.205],
                [0.996, 0.909, 0.218],
            ],
            // Moreland's smooth cool-warm map (interpolated in his Msh space between
            // sRGB (59, 76, 192) and (180, 4, 38) through (221, 221, 221)), sampled at
            // 33 points: what matplotlib's `coolwarm` draws, to a level or two. Five
            // stops drew kinks at the quarters, up to 18 levels off between them.
            ColourMap::CoolWarm => &[
                [0.231, 0.298, 0.753],
                [0.268, 0.352, 0.801],
                [0.305, 0.406, 0.844],
                [0.344, 0.458, 0.883],
                [0.384, 0.509, 0.917],
                [0.425, 0.558, 0.945],
                [0.467, 0.604, 0.968],
                [0.510, 0.648, 0.985],
                [0.553, 0.689, 0.995],
                [0.597, 0.726, 1.000],
                [0.639, 0.759, 0.998],
                [0.682, 0.789, 0.990],
                [0.722, 0.814, 0.976],
                [0.762, 0.834, 0.957],
                [0.799, 0.850, 0.932],
                [0.833, 0.860, 0.901],
                [0.865, 0.865, 0.865],
                [0.898, 0.849, 0.821],
                [0.924, 0.827, 0.775],
                [0.945, 0.801, 0.727],
                [0.959, 0.770, 0.678],
                [0.968, 0.734, 0.629],
                [0.970, 0.695, 0.579],
                [0.967, 0.651, 0.530],
                [0.958, 0.603, 0.482],
                [0.944, 0.552, 0.434],
                [0.924, 0.498, 0.388],
                [0.899, 0.440, 0.343],
                [0.870, 0.379, 0.300],
                [0.835, 0.313, 0.259],
                [0.796, 0.242, 0.220],
                [0.753, 0.157, 0.183],
                [0.706, 0.016, 0.149],
            ],
            ColourMap::Grey => &[[0.1, 0.1, 0.1], [0.95, 0.95, 0.95]],
        }
    }

    /// The linear RGB colour at `t` in [0, 1] (clamped; NaN maps to 0).
    pub fn colour(self, t: f32) -> [f32; 3] {
        let stops = self.stops();
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let x = t * (stops.len() - 1) as f32;
        let i = (x.floor() as usize).min(stops.len() - 2);
        let f = x - i as f32;
        let (a, b) = (stops[i], stops[i + 1]);
        [0, 1, 2].map(|k| crate::renderer::srgb_to_linear(a[k] + (b[k] - a[k]) * f))
    }
}

/// Which colours the species of mdlod's palette (type numbers, names of no element)
/// take where no colour is given them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Palette {
    /// The file's own colours.
    #[default]
    Default,
    /// Okabe and Ito's seven colours (2008), told apart with the common colour-vision
    /// deficiencies, the first three also in grey print ([`OKABE_ITO`]): palette slot
    /// `k` takes the `k mod 7`th (black, their eighth, is left out: shaded black
    /// spheres show no shape).
    OkabeIto,
}

/// Okabe and Ito's colours, sRGB, in an order whose first three differ most in
/// lightness (CIE L* 71, 46 and 89), so that the common figures of two or three species
/// also print in grey: orange, blue, yellow, vermilion, bluish green, sky blue, reddish
/// purple. (In their own order the first two, orange and sky blue, are equally light.)
pub const OKABE_ITO: [[u8; 3]; 7] = [
    [0xe6, 0x9f, 0x00],
    [0x00, 0x72, 0xb2],
    [0xf0, 0xe4, 0x42],
    [0xd5, 0x5e, 0x00],
    [0x00, 0x9e, 0x73],
    [0x56, 0xb4, 0xe9],
    [0xcc, 0x79, 0xa7],
];

/// Palette slots looked for in a file's colours (a file of more types than this keeps
/// the others' colours).
const PALETTE_SLOTS: usize = 256;

impl Palette {
    /// The colour (linear RGB) a species of `colour` in the file takes: under
    /// [`Palette::OkabeIto`], palette slot `k`'s colour ([`mdlod_format::meta::palette_colour`])
    /// becomes the `k mod 7`th of [`OKABE_ITO`]; any other colour (an element's) stays.
    pub fn colour(self, colour: [f32; 3]) -> [f32; 3] {
        match self {
            Palette::Default => colour,
            Palette::OkabeIto => palette_slot(colour, PALETTE_SLOTS).map_or(colour, |k| {
                mdlod_format::meta::srgb_to_linear(OKABE_ITO[k % OKABE_ITO.len()])
            }),
        }
    }
}

/// The palette slot below `slots` whose colour `colour` is (linear RGB, as files keep
/// it; within 1e-4 a channel), if any.
pub fn palette_slot(colour: [f32; 3], slots: usize) -> Option<usize> {
    (0..slots).find(|&k| {
        let p = mdlod_format::meta::palette_colour_linear(k);
        (0..3).all(|i| (p[i] - colour[i]).abs() <= 1e-4)
    })
}

/// The look of the points of a cut.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointStyle {
    /// Species named here change; the others keep the file's look.
    pub species: Vec<SpeciesStyle>,
    /// Multiplies every radius, particles' and clusters'.
    pub radius_scale: f32,
    /// Colour by the scalar attribute instead of by species.
    pub colour_map: Option<ColourMap>,
    /// The colours species of the palette take where `species` gives them none.
    #[serde(default, skip_serializing_if = "is_default_palette")]
    pub palette: Palette,
    /// Which of the file's attributes the colour map, splat intensities and hidden
    /// values read (a file of format 1.2 keeps several); `None`: the first. See
    /// [`crate::open_styled`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attribute: Option<String>,
    /// The attribute values that map to the colour map's ends (and to splat
    /// intensities 0 and 1), instead of the file's own range: the same in every frame of
    /// a trajectory, so that a colour means one value throughout a movie.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attribute_range: Option<[f32; 2]>,
    /// `attribute_range` was chosen by mdlod (the particles drawn where some are hidden
    /// or cut away, a movie's frames), not given: splats lit by the attribute keep the
    /// light's zero where the file's own range puts it ([`Self::light_range`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub range_derived: bool,
    /// Map the attribute's logarithm instead of its value (densities, energies spanning
    /// decades); see [`AttributeScale::with_log`].
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub log_scale: bool,
    /// Planes `[nx, ny, nz, d]` that cut the points away: only particles with `n·p ≤ d`
    /// for every plane are drawn (see [`crate::TraversalSettings::clip`]). Sphere,
    /// splat and S-NDF modes; the density volume clips its samples instead
    /// ([`crate::density::DensitySettings::clip`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clip: Vec<[f32; 4]>,
    /// Attribute values `[lo, hi]` (inclusive; an infinite end leaves that side open)
    /// whose particles are drawn as nothing, as hidden species are (OVITO's expression
    /// selection and delete: `--hide-attribute 0.5:1.5` leaves out a CNA column's fcc
    /// atoms). At most [`mdlod_format::reader::MAX_HIDDEN_RANGES`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hidden_values: Vec<[f32; 2]>,
    /// The attribute `hidden_values` are read against, where not [`Self::attribute`]
    /// (see [`crate::open_styled`]); `None`: the same one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hide_by: Option<String>,
    /// Further hidden value ranges, each read against the attribute it names
    /// (`--hide-attribute c_pe=:-3.5`): a particle any range of either list holds is
    /// left out, so that one view hides by several columns (a CNA's fcc atoms and the
    /// low energies). With `hidden_values`, at most
    /// [`mdlod_format::reader::MAX_HIDDEN_RANGES`] in all.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hidden_named: Vec<(String, [f32; 2])>,
}

fn is_default_palette(p: &Palette) -> bool {
    *p == Palette::Default
}

impl Default for PointStyle {
    fn default() -> Self {
        PointStyle {
            species: vec![],
            radius_scale: 1.0,
            colour_map: None,
            palette: Palette::Default,
            attribute: None,
            attribute_range: None,
            log_scale: false,
            clip: Vec::new(),
            hidden_values: Vec::new(),
            hide_by: None,
            hidden_named: Vec::new(),
            range_derived: false,
        }
    }
}

impl PointStyle {
    /// The range splats lit by the attribute `info` take their light from: the shown
    /// range, except that one mdlod chose ([`Self::range_derived`]) keeps the light's
    /// zero where the file's own range puts it: at 0 for a quantity whose logarithm the
    /// file keeps (`quantity`; none then), at the file's smallest value for a linear one
    /// (or the range's low end below it). The particles drawn of a column density with
    /// its thin gas hidden lit `σ − 10^lo` with `lo` their smallest, and a movie's frames
    /// lit less their union's smallest: totals 18-36 % low, with no word.
    pub fn light_range(
        &self,
        info: &mdlod_format::meta::AttributeInfo,
        quantity: bool,
    ) -> Option<[f32; 2]> {
        match (self.attribute_range, self.range_derived) {
            (Some(_), true) if quantity => None,
            (Some([lo, hi]), true) => Some([lo.min(info.min), hi]),
            (range, _) => range,
        }
    }

    /// True when the style draws points at other sizes than the file's: occlusion
    /// culling, which assumes the file's radii, must then be off. (Hidden particles are
    /// left out of the cut by the traversal, which occludes with what it draws only.)
    pub fn changes_geometry(&self) -> bool {
        self.radius_scale != 1.0 || self.species.iter().any(|s| s.radius.is_some())
    }

    /// The particles this style leaves out of a file with metadata `meta`, as the
    /// traversal takes them ([`crate::TraversalSettings::hidden`]): its hidden species
    /// ([`Self::hidden_mask`]) and, where the file has an attribute, its hidden values
    /// (none past [`mdlod_format::reader::MAX_HIDDEN_RANGES`] or of a range that is not
    /// one, which [`Self::validate`] refuses).
    pub fn hidden_set(&self, meta: &mdlod_format::meta::Metadata) -> crate::HiddenSet {
        let species = crate::HiddenSet::of_species(self.hidden_mask(&meta.species));
        let names = self.hide_names();
        let plain = self
            .hidden_values
            .iter()
            .filter(|_| meta.attribute.is_some())
            .map(|&r| (0u8, r));
        let named = self.hidden_named.iter().map(|(name, r)| {
            let slot = names.iter().position(|n| n == name).unwrap_or_default() + 1;
            (slot as u8, *r)
        });
        let ranges: Vec<(u8, [f32; 2])> = plain.chain(named).collect();
        species.with_slotted_ranges(&ranges).unwrap_or(species)
    }

    /// The attributes [`Self::hidden_named`] reads, each once, in the order of their
    /// first range: slot `k + 1` of [`Self::hidden_set`] reads the `k`-th, as
    /// [`mdlod_format::MdlodFile::hide_by_attributes`] takes them.
    pub fn hide_names(&self) -> Vec<&str> {
        let mut names: Vec<&str> = Vec::new();
        for (name, _) in &self.hidden_named {
            if !names.contains(&name.as_str()) {
                names.push(name);
            }
        }
        names
    }

    /// Some particles are hidden by their values (either list of ranges).
    pub fn hides_values(&self) -> bool {
        !self.hidden_values.is_empty() || !self.hidden_named.is_empty()
    }

    /// True when the style leaves particles out: hidden species or values, or clip
    /// planes (the particles drawn may then span less than the file's range).
    pub fn leaves_some_out(&self) -> bool {
        !self.clip.is_empty() || self.hides_values() || self.species.iter().any(|s| s.hidden)
    }

    /// The species table (linear colour, radius) after styling; hidden species get
    /// radius 0, which draws nothing. A style naming a species the file lacks is an
    /// error that lists the file's species.
    pub fn species_table(
        &self,
        species: &[mdlod_format::meta::Species],
    ) -> Result<Vec<[f32; 4]>, String> {
        if let Some(st) = self
            .species
            .iter()
            .find(|st| !species.iter().any(|s| s.name == st.name))
        {
            let names: Vec<&str> = species.iter().map(|s| s.name.as_str()).collect();
            // A file of LAMMPS type numbers, styled by an element's name.
            let numbered =
                names.iter().all(|n| n.parse::<u32>().is_ok()) && st.name.parse::<u32>().is_err();
            let hint = if numbered && names.len() == 1 {
                format!(
                    "; its species are type numbers: name the type here ({}), or convert \
                     with --species-name {}={} to call it so",
                    names[0], names[0], st.name
                )
            } else if numbered {
                format!(
                    "; its species are type numbers: name the type here (one of {}), or \
                     convert with --species-name TYPE={} (the type's number) to call it so",
                    names.join(", "),
                    st.name
                )
            } else {
                String::new()
            };
            return Err(format!(
                "no species named {:?} (the file's species are named {}){hint}",
                st.name,
                names.join(", ")
            ));
        }
        Ok(species
            .iter()
            .map(|s| {
                let st = self.style_of(&s.name).cloned().unwrap_or_default();
                let c = st.colour.unwrap_or_else(|| self.palette.colour(s.colour));
                let r = if st.hidden {
                    0.0
                } else {
                    st.radius.unwrap_or(s.radius) * self.radius_scale
                };
                [c[0], c[1], c[2], r]
            })
            .collect())
    }

    /// [`Self::clip`] as the traversal takes it; an error says what is wrong with a plane.
    pub fn clip_planes(&self) -> Result<crate::ClipPlanes, String> {
        crate::ClipPlanes::new(&self.clip)
    }

    /// The style given the species `name` (the last given, as the command line's later
    /// options override earlier ones), if any.
    fn style_of(&self, name: &str) -> Option<&SpeciesStyle> {
        self.species.iter().rfind(|st| st.name == name)
    }

    /// The species this style hides, as a mask of species indices for
    /// [`crate::TraversalSettings::hidden_species`]; 0 when none is hidden, or when one
    /// of index 64 or more is (clusters then still hold hidden species' particles).
    pub fn hidden_mask(&self, species: &[mdlod_format::meta::Species]) -> u64 {
        let mut mask = 0u64;
        for (i, s) in species.iter().enumerate() {
            let hidden = self.style_of(&s.name).is_some_and(|st| st.hidden);
            if hidden {
                if i >= 64 {
                    return 0;
                }
                mask |= 1 << i;
            }
        }
        mask
    }

    /// Of `species`, those a colour map leaves in colours of their own (bit `s` for
    /// species index `s`, among the first 64): the species given a colour, not hidden,
    /// where the style has a colour map (`--colour-map viridis --species-colour
    /// wall=grey`). Their values take no part of the map's range.
    pub fn unmapped_mask(&self, species: &[mdlod_format::meta::Species]) -> u64 {
        if self.colour_map.is_none() {
            return 0;
        }
        let mut mask = 0u64;
        for (i, s) in species.iter().enumerate().take(64) {
            let own = self
                .style_of(&s.name)
                .is_some_and(|st| st.colour.is_some() && !st.hidden);
            if own {
                mask |= 1 << i;
            }
        }
        mask
    }

    /// True when the style hides a species the traversal cannot leave out (one of index
    /// 64 or more: [`Self::hidden_mask`] is then 0 and the GPU hides its particles by
    /// their radius): occlusion culling, which would take them for occluders, must then
    /// be off.
    pub fn hides_past_the_mask(&self, species: &[mdlod_format::meta::Species]) -> bool {
        self.species.iter().any(|s| s.hidden) && self.hidden_mask(species) == 0
    }

    /// Whether occlusion culling may draw this style over a file of `species`: the
    /// spheres it draws are the file's ([`Self::changes_geometry`]), and what it hides
    /// the traversal leaves out ([`Self::hides_past_the_mask`]).
    pub fn culls(&self, species: &[mdlod_format::meta::Species]) -> bool {
        !self.changes_geometry() && !self.hides_past_the_mask(species)
    }

    /// The affine map that recolours clusters when species take other colours, `None`
    /// when none does (or a colour map colours the points): rows of `[a b c d]`, a colour
    /// `x` going to `a·x + d` per channel ([`recoloured`]).
    ///
    /// A cluster's stored colour is the area-weighted mean `C = Σ wᵢ cᵢ` of its
    /// particles' species colours (`Σ wᵢ = 1`). A map `M` with `M cᵢ = c′ᵢ` for every
    /// species turns it into `M C = Σ wᵢ c′ᵢ`, the mean of the new colours, with no
    /// per-species composition stored; as the weights sum to 1 it may be affine, which
    /// also tells apart colours on one line through black (white hydrogen and grey
    /// carbon). With `ĉ = [c; 1]`: `M = [I | 0] + (C′ − C) Ĉ⁺`, `C` and `C′` the 3×k
    /// matrices of the old and new colours and `Ĉ⁺` the pseudo-inverse of the 4×k
    /// `Ĉ`. It is exact for up to four species whose colours are affinely independent
    /// (and the identity on colours no species mixture makes); with more species, the
    /// least-squares fit of the species' new colours. `species` are the file's, `styled`
    /// the [`Self::species_table`].
    pub fn cluster_recolour(
        &self,
        species: &[mdlod_format::meta::Species],
        styled: &[[f32; 4]],
    ) -> Option<[[f32; 4]; 3]> {
        // Hidden species are in no cluster drawn (see [`Self::hidden_mask`]): the map
        // need only fit the others.
        let mask = self.hidden_mask(species);
        let (species, styled): (Vec<&mdlod_format::meta::Species>, Vec<&[f32; 4]>) = species
            .iter()
            .zip(styled)
            .enumerate()
            .filter(|(i, _)| !in_species_set(mask, *i))
            .map(|(_, p)| p)
            .unzip();
        if self.colour_map.is_some()
            || species
                .iter()
                .zip(&styled)
                .all(|(s, t)| s.colour == [t[0], t[1], t[2]])
        {
            return None;
        }
        let k = species.len();
        let c: Vec<[f64; 4]> = species
            .iter()
            .map(|s| {
                let [r, g, b] = s.colour.map(f64::from);
                [r, g, b, 1.0]
            })
            .collect();
        let d: Vec<[f64; 3]> = species
            .iter()
            .zip(&styled)
            .map(|(s, t)| [0, 1, 2].map(|i| f64::from(t[i]) - f64::from(s.colour[i])))
            .collect();
        // Ĉ⁺ (k×4) from the smaller Gram matrix, regularised a little so that dependent
        // colours give the least-squares fit instead of a singular system.
        let pinv: Vec<[f64; 4]> = if k <= 4 {
            // (ĈᵀĈ + εI)⁻¹ Ĉᵀ
            let mut g: Vec<f64> = (0..k * k).map(|ij| dot4(&c[ij / k], &c[ij % k])).collect();
            let eps = 1e-9 * (0..k).map(|i| g[i * k + i]).sum::<f64>().max(1e-30);
            (0..k).for_each(|i| g[i * k + i] += eps);
            let inv = invert(k, g)?;
            (0..k)
                .map(|i| [0, 1, 2, 3].map(|col| (0..k).map(|j| inv[i * k + j] * c[j][col]).sum()))
                .collect()
        } else {
            // Ĉᵀ (ĈĈᵀ + εI)⁻¹
            let mut g: Vec<f64> = (0..16)
                .map(|ij| c.iter().map(|v| v[ij / 4] * v[ij % 4]).sum())
                .collect();
            let eps = 1e-9 * (g[0] + g[5] + g[10] + g[15]).max(1e-30);
            [0, 5, 10, 15].iter().for_each(|&i| g[i] += eps);
            let inv = invert(4, g)?;
            c.iter()
                .map(|v| [0, 1, 2, 3].map(|col| (0..4).map(|j| v[j] * inv[j * 4 + col]).sum()))
                .collect()
        };
        let mut t = [[0.0f32; 4]; 3];
        for (row, out) in t.iter_mut().enumerate() {
            for (col, v) in out.iter_mut().enumerate() {
                let identity = if row == col { 1.0 } else { 0.0 };
                let change: f64 = (0..k).map(|i| d[i][row] * pinv[i][col]).sum();
                *v = (identity + change) as f32;
            }
        }
        t.iter().flatten().all(|v| v.is_finite()).then_some(t)
    }

    /// How far (largest channel difference, linear) the clusters' recolouring misses
    /// a species' new colour: 0 where it is exact, more for a least-squares map (more
    /// than four species, or colours affinely dependent); `None` when nothing is
    /// recoloured or a species is unknown.
    pub fn recolour_miss(&self, species: &[mdlod_format::meta::Species]) -> Option<f32> {
        let styled = self.species_table(species).ok()?;
        let map = self.cluster_recolour(species, &styled)?;
        let mask = self.hidden_mask(species);
        species
            .iter()
            .zip(&styled)
            .enumerate()
            .filter(|(i, _)| !in_species_set(mask, *i))
            .map(|(_, (s, t))| {
                let c = recoloured(&map, s.colour);
                (0..3).map(|k| (c[k] - t[k]).abs()).fold(0.0f32, f32::max)
            })
            .reduce(f32::max)
    }

    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.radius_scale.is_finite() && self.radius_scale > 0.0) {
            return Err(format!(
                "radius scale {} (must be positive)",
                self.radius_scale
            ));
        }
        for s in &self.species {
            if s.radius.is_some_and(|r| !(r.is_finite() && r > 0.0)) {
                return Err(format!(
                    "species {}: radius {} (must be positive)",
                    s.name,
                    s.radius.unwrap_or_default()
                ));
            }
            if s.colour.is_some_and(|c| {
                c.iter()
                    .any(|v| !(v.is_finite() && (0.0..=1.0).contains(v)))
            }) {
                return Err(format!(
                    "species {}: colour {:?} (each channel in [0, 1])",
                    s.name, s.colour
                ));
            }
        }
        let ranges = self.hidden_values.len() + self.hidden_named.len();
        if ranges > mdlod_format::reader::MAX_HIDDEN_RANGES {
            return Err(format!(
                "{ranges} hidden value ranges (at most {})",
                mdlod_format::reader::MAX_HIDDEN_RANGES
            ));
        }
        if let Some([lo, hi]) = self
            .hidden_values
            .iter()
            .chain(self.hidden_named.iter().map(|(_, r)| r))
            .find(|[lo, hi]| lo.is_nan() || hi.is_nan() || lo > hi)
        {
            return Err(format!(
                "hidden value range {lo} to {hi} (the second not below the first)"
            ));
        }
        if let Some([lo, hi]) = self.attribute_range {
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(format!(
                    "attribute range {lo} to {hi} (finite, the second above the first)"
                ));
            }
        }
        Ok(())
    }
}

/// How the scalar attribute maps to [0, 1] for colour maps and splat intensities:
/// linearly from the file's range (`min` to 0, `max` to 1), an affine map, so that a
/// cluster's area-weighted mean attribute maps to the mean of its particles' values. A
/// constant attribute (equal-mass SPH particles, say), whose range is empty or no wider
/// than the single-precision rounding of its values, maps every value to 1: every point
/// the same full light or the map's last colour, particles and clusters alike (its
/// particles are quantized to 0 and its cluster means carry rounding noise, neither of
/// which means anything).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AttributeScale {
    min: f32,
    max: f32,
    constant: bool,
    /// The range shown instead of `min..max` ([`PointStyle::attribute_range`]).
    shown: Option<[f32; 2]>,
    /// Logarithmic: `ln v` mapped from `ln lo` to `ln hi` ([`Self::with_log`]).
    log: bool,
    /// The attribute holds base-10 logarithms and the light is the quantity itself
    /// ([`Self::lighting_by_quantity`]).
    exp10: bool,
}

impl AttributeScale {
    /// For splats lit by an attribute stored as its logarithm (a file's
    /// `attribute_log10`, whose clusters hold the logarithm of their mean value): a
    /// value `v` maps to `10^(v − max)` and the light unit is `10^max`, so that the light
    /// is the quantity `10^v` itself and sums over clusters as over their particles.
    /// With a range `lo..hi` (logarithms), the light is `10^v` clamped to `10^lo..10^hi`,
    /// less `10^lo`, as a linear range's light is the value less its low end.
    pub fn lighting_by_quantity(self) -> Self {
        AttributeScale {
            exp10: true,
            log: false,
            ..self
        }
    }

    /// The top of the range a quantity's logarithm is lit up to ([`Self::exp10`]).
    fn exp10_top(&self) -> f64 {
        f64::from(self.shown.map_or(self.max, |[_, hi]| hi))
    }

    /// The quantities a logarithm's light starts and ends at ([`Self::exp10`]): with a
    /// range `lo..hi` given, `10^lo` and `10^hi` (the light is the quantity clamped to
    /// them, less `10^lo`, as a linear range's is the value less its low end); else 0
    /// and `10^max`.
    fn exp10_ends(&self) -> (f64, f64) {
        match self.shown {
            Some([lo, hi]) => (10f64.powf(f64::from(lo)), 10f64.powf(f64::from(hi))),
            None => (0.0, 10f64.powf(f64::from(self.max))),
        }
    }
    /// Ranges at most this many units in the last place of their values wide are
    /// rounding, not data.
    const ROUNDING_ULPS: f64 = 8.0;

    pub fn new(info: &mdlod_format::meta::AttributeInfo) -> Self {
        let (min, max) = (f64::from(info.min), f64::from(info.max));
        let rounding = Self::ROUNDING_ULPS * f64::from(f32::EPSILON) * min.abs().max(max.abs());
        AttributeScale {
            min: info.min,
            max: info.max,
            // Also constant: a range that is no range (non-finite or reversed ends).
            constant: !(max - min > rounding && (max - min).is_finite()),
            shown: None,
            log: false,
            exp10: false,
        }
    }

    /// The largest span of a log scale, in factors of 10: where the range's low end is 0
    /// or below (a kinetic energy from 0), the scale starts this many decades below its
    /// high end, and values at or below that take the map's first colour.
    pub const LOG_DECADES: f64 = 4.0;

    /// This scale on a logarithmic axis: a value `v` maps to `(ln v − ln lo) / (ln hi −
    /// ln lo)` over the shown range (or the file's), clamped; with a low end of 0 or
    /// below, `lo` is `hi / 10^LOG_DECADES` ([`Self::log_range`]). A cluster's mean maps
    /// through the same curve (the log of a mean, not the mean of logs). A range without
    /// a positive high end stays linear.
    pub fn with_log(self, log: bool) -> Self {
        AttributeScale { log, ..self }
    }

    /// The ends a log scale maps, `None` when it is linear (not asked for, a constant
    /// attribute, or no positive high end).
    pub fn log_range(&self) -> Option<[f64; 2]> {
        if !self.log {
            return None;
        }
        let (lo, hi) = match self.shown {
            Some([lo, hi]) => (f64::from(lo), f64::from(hi)),
            None if self.constant => return None,
            None => (f64::from(self.min), f64::from(self.max)),
        };
        if !(hi > 0.0 && hi.is_finite()) {
            return None;
        }
        let floor = hi / 10f64.powf(Self::LOG_DECADES);
        let lo = if lo > 0.0 { lo.min(hi) } else { floor };
        (hi > lo).then_some([lo, hi])
    }

    /// The file's attribute (`info`) shown over `range` instead of its own: values map
    /// linearly from `range` to [0, 1], clamped, a constant attribute included.
    pub fn with_range(info: &mdlod_format::meta::AttributeInfo, range: Option<[f32; 2]>) -> Self {
        AttributeScale {
            shown: range,
            ..Self::new(info)
        }
    }

    /// True when the attribute is constant (every value maps to 1).
    pub fn is_constant(&self) -> bool {
        self.constant
    }

    /// The light of a splat lit by this attribute is the value it maps to ([0, 1]) times
    /// this factor: on a linear scale the range's width, so that the light is `v − lo`
    /// (clamped to the range) in the attribute's own units and an image's light is the
    /// projection of `v − lo` (with the range from 0, of `v` itself); a constant
    /// attribute's positive value (its points' light is that value); 1 otherwise (a log
    /// scale's position, a constant at or below 0: the light is then the flux).
    pub fn light_unit(&self) -> f32 {
        self.light_in_units().map_or(1.0, |(_, unit)| unit)
    }

    /// What the light of splats lit by this attribute projects ([`Self::light_unit`]):
    /// `Some(lo)` where it is `v − lo` in the attribute's units (`lo` 0 for `v` itself),
    /// `None` where it is no quantity in those units (a log scale, a constant attribute
    /// at or below 0, a range of no width).
    pub fn light_zero(&self) -> Option<f32> {
        self.light_in_units().map(|(zero, _)| zero)
    }

    /// Where the light is a quantity in the attribute's units: the value its 0 stands
    /// for and the factor of its 1 ([`Self::light_unit`], [`Self::light_zero`]).
    fn light_in_units(&self) -> Option<(f32, f32)> {
        if self.exp10 {
            let (zero, top) = self.exp10_ends();
            let (zero32, unit) = (zero as f32, (top - zero) as f32);
            return (unit > 0.0 && unit.is_finite() && zero32.is_finite())
                .then_some((zero32, unit));
        }
        if self.log_range().is_some() {
            return None;
        }
        let (lo, hi) = match self.shown {
            Some([lo, hi]) => (lo, hi),
            None if self.constant => return (self.min > 0.0).then_some((0.0, self.min)),
            None => (self.min, self.max),
        };
        // (A width past single precision: the light is the flux.)
        let span = hi - lo;
        (span > 0.0 && span.is_finite()).then_some((lo, span))
    }

    /// A value (a cluster's mean) in [0, 1].
    pub fn of_value(&self, v: f32) -> f32 {
        if self.exp10 {
            // Without a range, relative to the top (no overflow for any logarithm).
            let t = match self.shown {
                None => 10f64.powf(f64::from(v) - self.exp10_top()),
                Some(_) => {
                    let (zero, top) = self.exp10_ends();
                    (10f64.powf(f64::from(v)).clamp(zero, top) - zero) / (top - zero)
                }
            };
            return if t.is_nan() {
                0.0
            } else {
                t.clamp(0.0, 1.0) as f32
            };
        }
        if let Some([lo, hi]) = self.log_range() {
            let v = f64::from(v);
            if v.is_nan() || v <= lo {
                return 0.0;
            }
            return ((v.ln() - lo.ln()) / (hi.ln() - lo.ln())).clamp(0.0, 1.0) as f32;
        }
        let (lo, hi) = match self.shown {
            Some([lo, hi]) => (lo, hi),
            None if self.constant => return 1.0,
            None => (self.min, self.max),
        };
        let span = hi - lo;
        let t = if span.is_finite() {
            (v - lo) / span
        } else {
            // Ends of opposite signs near f32::MAX: their difference overflows f32.
            ((f64::from(v) - f64::from(lo)) / (f64::from(hi) - f64::from(lo))) as f32
        };
        if t.is_nan() {
            0.0
        } else {
            t.clamp(0.0, 1.0)
        }
    }

    /// A particle's quantized value `q` (FORMAT.md: `min + (max − min) · q / 65535`) in
    /// [0, 1].
    pub fn of_quantized(&self, q: u16) -> f32 {
        if self.shown.is_some() || self.log_range().is_some() || self.exp10 {
            let (min, max) = (f64::from(self.min), f64::from(self.max));
            let value = if self.constant {
                min
            } else {
                min + (max - min) * f64::from(q) / 65535.0
            };
            self.of_value(value as f32)
        } else if self.constant {
            1.0
        } else {
            f32::from(q) / 65535.0
        }
    }
}

fn dot4(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

/// The inverse of the `n`×`n` row-major matrix `m` by Gauss-Jordan elimination with
/// partial pivoting; `None` when it is singular.
fn invert(n: usize, mut m: Vec<f64>) -> Option<Vec<f64>> {
    let mut inv: Vec<f64> = (0..n * n)
        .map(|ij| if ij / n == ij % n { 1.0 } else { 0.0 })
        .collect();
    for col in 0..n {
        let pivot =
            (col..n).max_by(|&a, &b| m[a * n + col].abs().total_cmp(&m[b * n + col].abs()))?;
        if m[pivot * n + col].abs() < 1e-300 {
            return None;
        }
        for j in 0..n {
            m.swap(col * n + j, pivot * n + j);
            inv.swap(col * n + j, pivot * n + j);
        }
        let p = m[col * n + col];
        for j in 0..n {
            m[col * n + j] /= p;
            inv[col * n + j] /= p;
        }
        for row in (0..n).filter(|&r| r != col) {
            let f = m[row * n + col];
            for j in 0..n {
                m[row * n + j] -= f * m[col * n + j];
                inv[row * n + j] -= f * inv[col * n + j];
            }
        }
    }
    Some(inv)
}

/// A linear colour through a [`PointStyle::cluster_recolour`] map.
pub fn recoloured(t: &[[f32; 4]; 3], c: [f32; 3]) -> [f32; 3] {
    t.map(|row| row[0] * c[0] + row[1] * c[1] + row[2] * c[2] + row[3])
}

/// The linear colour of a colour packed for the GPU ([`pack_colour`]).
pub fn unpack_colour(c: u32) -> [f32; 3] {
    let t = &srgb_tables().to_linear;
    [0, 8, 16].map(|shift| t[((c >> shift) & 0xff) as usize])
}

/// Packs a linear RGB colour for the GPU as an 8-bit image stores colour: RGBA8, R in
/// the low byte, each channel sRGB-encoded (the shaders decode it, `points.wgsl`).
///
/// Why sRGB: linear bytes keep a step of 1/255 of light everywhere, which is far finer
/// than the eye needs in bright colours and far coarser in dark ones: a dark colour
/// map end (magma's, viridis') landed up to 7 levels off once shaded and written as
/// sRGB. sRGB bytes step as the eye does, so a colour comes back within half a level
/// of its sRGB value. Rounded to the nearest sRGB level, exactly; NaN packs as 0.
pub fn pack_colour(c: [f32; 3]) -> u32 {
    rgba(c.map(linear_to_srgb_byte))
}

/// Three channel bytes as RGBA8, R in the low byte, A 255.
fn rgba(b: [u32; 3]) -> u32 {
    b[0] | (b[1] << 8) | (b[2] << 16) | (255 << 24)
}

/// A node colour as the file stores it (linear RGBA8, `FORMAT.md`) packed for the GPU
/// ([`pack_colour`]): each byte through a table.
pub fn pack_file_colour(c: u32) -> u32 {
    let t = &srgb_tables().file_to_srgb;
    rgba([0, 8, 16].map(|shift| u32::from(t[((c >> shift) & 0xff) as usize])))
}

/// Buckets of the linear range the encoder's first guess comes from.
const SRGB_BUCKETS: usize = 4096;

struct SrgbTables {
    /// Linear light of each sRGB byte.
    to_linear: [f32; 256],
    /// `bounds[k]`: the linear light where sRGB byte `k + 1` becomes the nearest
    /// (the sRGB value `(k + 0.5) / 255` as light); `bounds[255]` is infinite.
    bounds: [f32; 256],
    /// The nearest sRGB byte at each bucket's lower end.
    first: [u8; SRGB_BUCKETS],
    /// The sRGB byte nearest each linear byte of the file's node colours.
    file_to_srgb: [u8; 256],
}

fn srgb_tables() -> &'static SrgbTables {
    static TABLES: std::sync::OnceLock<SrgbTables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        let to_linear = crate::renderer::srgb_to_linear;
        let mut t = SrgbTables {
            to_linear: [0.0; 256],
            bounds: [f32::INFINITY; 256],
            first: [0; SRGB_BUCKETS],
            file_to_srgb: [0; 256],
        };
        for k in 0..256 {
            t.to_linear[k] = to_linear(k as f32 / 255.0);
            if k < 255 {
                t.bounds[k] = to_linear((k as f32 + 0.5) / 255.0);
            }
        }
        let nearest = |v: f32, bounds: &[f32; 256]| bounds.partition_point(|&b| b <= v) as u8;
        for (i, f) in t.first.iter_mut().enumerate() {
            *f = nearest(i as f32 / SRGB_BUCKETS as f32, &t.bounds);
        }
        for (k, f) in t.file_to_srgb.iter_mut().enumerate() {
            *f = nearest(k as f32 / 255.0, &t.bounds);
        }
        t
    })
}

/// The nearest sRGB byte of one linear channel, clamped to [0, 1] (NaN: 0).
fn linear_to_srgb_byte(v: f32) -> u32 {
    let t = srgb_tables();
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    let mut k = t.first[((v * SRGB_BUCKETS as f32) as usize).min(SRGB_BUCKETS - 1)] as usize;
    while t.bounds[k] <= v {
        k += 1;
    }
    k as u32
}

#[cfg(test)]
mod tests {
    /// Splats lit by a quantity kept as its logarithm: the light is `10^v` itself, in
    /// units of `10^max`; with a range of logarithms, `10^v` clamped to its ends less the
    /// low one, as a linear range's light is the value less its low end.
    #[test]
    fn a_logarithm_lights_by_its_quantity_less_a_ranges_low_end() {
        use super::AttributeScale;
        let info = mdlod_format::meta::AttributeInfo {
            name: "log10(sigma)".into(),
            min: -2.0,
            max: 6.0,
            log10: false,
        };
        let close = |a: f32, b: f64| (f64::from(a) - b).abs() <= 1e-6 * b.abs().max(1e-6);
        let whole = AttributeScale::new(&info).lighting_by_quantity();
        assert_eq!(whole.of_value(6.0), 1.0);
        assert!(close(whole.of_value(4.0), 0.01));
        assert!(close(whole.of_value(-2.0), 1e-8));
        assert!(close(whole.light_unit(), 1e6));
        assert_eq!(whole.light_zero(), Some(0.0));
        let ranged = AttributeScale::with_range(&info, Some([2.0, 3.0])).lighting_by_quantity();
        assert_eq!(ranged.of_value(1.0), 0.0);
        assert_eq!(ranged.of_value(2.0), 0.0);
        assert!(close(
            ranged.of_value(2.5),
            (10f64.powf(2.5) - 100.0) / 900.0
        ));
        assert_eq!(ranged.of_value(3.0), 1.0);
        assert_eq!(ranged.of_value(5.0), 1.0);
        assert!(close(ranged.light_unit(), 900.0));
        assert_eq!(ranged.light_zero(), Some(100.0));
        // A particle's stored value is mapped as a cluster's mean is.
        assert_eq!(ranged.of_quantized(0), 0.0);
        assert_eq!(ranged.of_quantized(u16::MAX), 1.0);
    }

    /// The ranges chosen where none is given: splats lit from 0, a log scale from the
    /// smallest value above 0, a diverging map centred on 0; the values' own elsewhere.
    #[test]
    fn default_ranges_start_at_zero_the_floor_or_the_centre() {
        use super::{default_range, ColourMap, RangeChoice::*};
        let warm = Some(ColourMap::CoolWarm);
        assert_eq!(
            default_range([2.0, 8.0], true, false, false, None, None),
            Some(([0.0, 8.0], FromZero))
        );
        assert_eq!(
            default_range([-2.0, 8.0], true, false, false, None, None),
            None
        );
        assert_eq!(
            default_range([0.0, 100.0], false, true, true, None, Some(1e-3)),
            Some(([1e-3, 100.0], LogFloor))
        );
        // A floor below 10⁻⁸ of the top is raised to it.
        assert_eq!(
            default_range([0.0, 100.0], false, true, true, None, Some(1e-12)),
            Some(([1e-6, 100.0], LogFloor))
        );
        assert_eq!(
            default_range([1.0, 100.0], false, true, true, None, Some(1.0)),
            None
        );
        assert_eq!(
            default_range([-2.0, 8.0], false, true, false, warm, None),
            Some(([-8.0, 8.0], Centred))
        );
        assert_eq!(
            default_range([-2.0, 8.0], false, false, false, warm, None),
            None
        );
        assert_eq!(
            default_range([2.0, 8.0], false, true, false, warm, None),
            None
        );
        assert_eq!(
            default_range(
                [-2.0, 8.0],
                false,
                true,
                false,
                Some(ColourMap::Viridis),
                None
            ),
            None
        );
    }

    fn look(name: &str, colour: [f32; 3], radius: f32) -> mdlod_format::meta::Species {
        mdlod_format::meta::Species {
            name: name.into(),
            radius,
            colour,
            radius_range: None,
        }
    }

    /// Names no frame holds together that took the same palette slot get apart: the
    /// later one takes the first palette colour no look has. A frame's own two names of
    /// one colour (given so) stay as they are.
    #[test]
    fn names_that_never_meet_do_not_share_a_palette_colour() {
        let slot = mdlod_format::meta::palette_colour_linear;
        // A solvent that evaporates, then ions: third in their frames' lists alike.
        let f0 = [
            look("LIP", slot(0), 0.5),
            look("W", slot(1), 0.5),
            look("SOL", slot(2), 0.5),
        ];
        let f1 = [
            look("LIP", slot(0), 0.5),
            look("W", slot(1), 0.5),
            look("ION", slot(2), 0.5),
        ];
        let looks = trajectory_looks(&[&f0, &f1]);
        let colours: Vec<[f32; 3]> = looks.iter().map(|s| s.colour).collect();
        assert_eq!(colours, [slot(0), slot(1), slot(2), slot(3)]);
        assert_eq!(looks[3].name, "ION");
        // The ions' frame draws them in their look's colour.
        let styled = keep_looks(&f1, &looks, &[]);
        assert_eq!(styled.len(), 1);
        assert_eq!(
            (styled[0].name.as_str(), styled[0].colour),
            ("ION", Some(slot(3)))
        );
        // Two names a frame gives one colour, or a colour not the palette's, stay.
        let f2 = [look("A", slot(2), 0.5), look("B", slot(2), 0.5)];
        let grey = [0.3, 0.3, 0.3];
        let f3 = [look("C", grey, 0.5)];
        let f4 = [look("D", grey, 0.5)];
        let looks = trajectory_looks(&[&f2, &f3, &f4]);
        let colours: Vec<[f32; 3]> = looks.iter().map(|s| s.colour).collect();
        assert_eq!(colours, [slot(2), slot(2), grey, grey]);
    }

    /// A name keeps the look of the frame with the most species (the earliest of them),
    /// a name that frame lacks that of its first frame; the user's styles win.
    #[test]
    fn species_keep_one_look_across_a_trajectory() {
        let (red, blue, pink) = ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.7, 0.7]);
        // Frame 0: B alone, as boron; frame 1: A and B as labels; frame 2: C appears.
        let f0 = [look("B", pink, 0.84)];
        let f1 = [look("A", red, 0.5), look("B", blue, 0.5)];
        let f2 = [look("C", red, 0.5)];
        let looks = trajectory_looks(&[&f0, &f1, &f2]);
        let names: Vec<&str> = looks.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["A", "B", "C"]);
        assert_eq!(looks[1], look("B", blue, 0.5));
        // Frame 0's B takes frame 1's colour and radius; frame 1 needs nothing.
        let b = keep_looks(&f0, &looks, &[]);
        assert_eq!(
            b,
            [SpeciesStyle {
                name: "B".into(),
                colour: Some(blue),
                radius: Some(0.5),
                hidden: false
            }]
        );
        assert!(keep_looks(&f1, &looks, &[]).is_empty());
        // A hidden species keeps no look: only the user's style is left.
        let hide_b = [SpeciesStyle {
            name: "B".into(),
            hidden: true,
            ..Default::default()
        }];
        assert_eq!(keep_looks(&f0, &looks, &hide_b), hide_b);
        // A frame whose B has frame 1's colour keeps its own radius: a particle that
        // grew over the run.
        let grown = [look("B", blue, 0.75)];
        assert!(keep_looks(&grown, &looks, &[]).is_empty());
        // A radius within 1 % is the same look; the user's colour wins, their styles of
        // species the frame lacks are dropped.
        let near = [look("B", pink, 0.503)];
        let user = [
            SpeciesStyle {
                name: "B".into(),
                colour: Some(red),
                ..Default::default()
            },
            SpeciesStyle {
                name: "A".into(),
                hidden: true,
                ..Default::default()
            },
        ];
        let styled = keep_looks(&near, &looks, &user);
        assert_eq!(
            styled,
            [SpeciesStyle {
                name: "B".into(),
                colour: Some(red),
                radius: None,
                hidden: false
            }]
        );
    }

    use super::*;

    #[test]
    fn a_log_scale_maps_decades_evenly_and_starts_below_a_zero_low_end() {
        let info = |min: f32, max: f32| mdlod_format::meta::AttributeInfo {
            name: "rho".into(),
            min,
            max,
            log10: false,
        };
        let log = AttributeScale::new(&info(1.0, 1000.0)).with_log(true);
        assert_eq!(log.log_range(), Some([1.0, 1000.0]));
        for (v, t) in [
            (1.0, 0.0),
            (10.0, 1.0 / 3.0),
            (100.0, 2.0 / 3.0),
            (1000.0, 1.0),
        ] {
            assert!(
                (log.of_value(v) - t).abs() < 1e-6,
                "{v}: {}",
                log.of_value(v)
            );
        }
        assert_eq!(log.of_value(0.5), 0.0);
        assert_eq!(log.of_value(f32::NAN), 0.0);
        assert_eq!(log.of_quantized(65535), 1.0);
        // Linear, as before, without it.
        let linear = AttributeScale::new(&info(1.0, 1000.0));
        assert!((linear.of_value(10.0) - 9.0 / 999.0).abs() < 1e-6);
        // From 0: four decades below the top; values at or below take the first colour.
        let from_zero = AttributeScale::new(&info(0.0, 2e4)).with_log(true);
        let [lo, hi] = from_zero.log_range().unwrap();
        assert!((lo - 2.0).abs() < 1e-9 && hi == 2e4, "{lo} {hi}");
        assert_eq!(from_zero.of_quantized(0), 0.0);
        assert!((from_zero.of_value(200.0) - 0.5).abs() < 1e-6);
        // A range given replaces the file's; no positive end, or a constant: linear.
        let shown = AttributeScale::with_range(&info(0.0, 2e4), Some([10.0, 1e3])).with_log(true);
        assert!((shown.of_value(100.0) - 0.5).abs() < 1e-6);
        assert_eq!(
            AttributeScale::new(&info(-5.0, -1.0))
                .with_log(true)
                .log_range(),
            None
        );
        assert_eq!(
            AttributeScale::new(&info(3.0, 3.0))
                .with_log(true)
                .of_value(3.0),
            1.0
        );
        // A range given from 0 (a movie's union of its frames' ranges) starts 4 decades
        // below its top too.
        let given = AttributeScale::with_range(&info(1.0, 2.0), Some([0.0, 100.0])).with_log(true);
        assert_eq!(given.log_range(), Some([0.01, 100.0]));
    }

    #[test]
    fn a_diverging_map_centres_signed_values_on_zero() {
        let c = ColourMap::CoolWarm;
        assert_eq!(c.centred_range([-2.0, 5.0]), Some([-5.0, 5.0]));
        assert_eq!(c.centred_range([-7.5, 0.5]), Some([-7.5, 7.5]));
        // One sign, or zero at an end: the values' own range.
        assert_eq!(c.centred_range([0.0, 5.0]), None);
        assert_eq!(c.centred_range([-3.0, -1.0]), None);
        assert_eq!(ColourMap::Viridis.centred_range([-2.0, 5.0]), None);
        // White is 0: the map's middle.
        let [lo, hi] = c.centred_range([-2.0, 5.0]).unwrap();
        assert_eq!((0.0 - lo) / (hi - lo), 0.5);
    }

    fn species(colours: &[[f32; 3]]) -> Vec<mdlod_format::meta::Species> {
        colours
            .iter()
            .enumerate()
            .map(|(i, &colour)| mdlod_format::meta::Species {
                name: format!("s{i}"),
                radius: 1.0,
                colour,
                radius_range: None,
            })
            .collect()
    }

    /// `--palette okabe-ito`: palette colours (of any slot, the generated ones past the
    /// tenth too) become Okabe and Ito's, an element's colour and a colour given stay,
    /// and clusters are recoloured with them; a trajectory's looks map alike.
    #[test]
    fn the_okabe_ito_palette_replaces_palette_colours_only() {
        use mdlod_format::meta::{palette_colour_linear, srgb_to_linear};
        let copper = srgb_to_linear([0xc8, 0x80, 0x33]);
        let file = species(&[
            palette_colour_linear(0),
            palette_colour_linear(1),
            copper,
            palette_colour_linear(12),
        ]);
        let oi = |k: usize| srgb_to_linear(OKABE_ITO[k]);
        let style = PointStyle {
            palette: Palette::OkabeIto,
            ..style_of(&[(1, [0.0, 0.0, 0.0])])
        };
        let table = style.species_table(&file).unwrap();
        let rgb = |t: [f32; 4]| [t[0], t[1], t[2]];
        assert_eq!(rgb(table[0]), oi(0));
        assert_eq!(rgb(table[1]), [0.0, 0.0, 0.0], "a colour given stays");
        assert_eq!(rgb(table[2]), copper, "an element's colour stays");
        assert_eq!(rgb(table[3]), oi(12 % 7));
        assert_eq!(palette_slot(copper, 256), None);
        // The first three print apart in grey: Rec. 709 luminances at least 0.1 apart.
        let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        let l: Vec<f32> = (0..3).map(|k| luma(oi(k))).collect();
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            assert!((l[a] - l[b]).abs() > 0.1, "{l:?}");
        }
        assert!(style.cluster_recolour(&file, &table).is_some());
        // The default palette changes nothing.
        let plain = PointStyle::default();
        let table = plain.species_table(&file).unwrap();
        assert!(file.iter().zip(&table).all(|(s, t)| s.colour == rgb(*t)));
        assert_eq!(plain.cluster_recolour(&file, &table), None);
        // A frame whose species took another palette slot in the trajectory's looks.
        let own = species(&[palette_colour_linear(2)]);
        let looks = species(&[palette_colour_linear(4)]);
        let styled = frame_styles(&own, &looks, &[], false, Palette::OkabeIto);
        assert_eq!(styled[0].colour, Some(oi(4)));
        let styled = frame_styles(&own, &looks, &[], false, Palette::Default);
        assert_eq!(styled[0].colour, Some(palette_colour_linear(4)));
    }

    /// A style giving species `s{i}` colour `c` for each `(i, c)`.
    fn style_of(new: &[(usize, [f32; 3])]) -> PointStyle {
        PointStyle {
            species: new
                .iter()
                .map(|&(i, c)| SpeciesStyle {
                    name: format!("s{i}"),
                    colour: Some(c),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        }
    }

    fn recolour_of(old: &[[f32; 3]], new: &[(usize, [f32; 3])]) -> Option<[[f32; 4]; 3]> {
        let style = style_of(new);
        let file = species(old);
        let table = style.species_table(&file).unwrap();
        style.cluster_recolour(&file, &table)
    }

    fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
    }

    /// Copper, silver and oxygen (linear), as a converted file colours them.
    const CU: [f32; 3] = [0.578, 0.216, 0.033];
    const AG: [f32; 3] = [0.527, 0.527, 0.527];
    const O: [f32; 3] = [1.0, 0.004, 0.004];

    /// Up to four species of affinely independent colours: every old colour goes to its
    /// new one, so every mixture goes to the same mixture of the new colours; species
    /// left alone keep theirs. White hydrogen and grey carbon lie on one line through
    /// black, which a linear map could not tell apart (hydrogen clusters turned green
    /// with carbon's new colour).
    #[test]
    fn recolouring_clusters_is_exact_for_up_to_four_independent_colours() {
        let red = [0.9, 0.05, 0.1];
        let blue = [0.05, 0.1, 0.8];
        let (h, c) = ([1.0, 1.0, 1.0], [0.279, 0.279, 0.279]);
        type Case<'a> = (&'a [[f32; 3]], &'a [(usize, [f32; 3])]);
        let cases: [Case<'_>; 6] = [
            (&[CU], &[(0, red)]),
            (&[CU, AG], &[(1, blue)]),
            (&[CU, AG, O], &[(0, red)]),
            (&[CU, AG, O], &[(0, blue), (1, red), (2, AG)]),
            (&[h, c], &[(1, [0.0, 1.0, 0.0])]),
            (&[h, c, O, CU], &[(1, [0.0, 1.0, 0.0]), (3, blue)]),
        ];
        for (old, new) in cases {
            let t = recolour_of(old, new).unwrap();
            let want: Vec<[f32; 3]> = (0..old.len())
                .map(|i| new.iter().find(|n| n.0 == i).map_or(old[i], |n| n.1))
                .collect();
            for (c, w) in old.iter().zip(&want) {
                assert!(close(recoloured(&t, *c), *w, 1e-5), "{old:?} {new:?}");
            }
            // A mixture of all of them, weights 0.4, 0.3, 0.2, 0.1 (renormalised).
            let wts = [0.4f32, 0.3, 0.2, 0.1];
            let sum: f32 = wts[..old.len()].iter().sum();
            let mix = |cs: &[[f32; 3]]| {
                [0, 1, 2].map(|k| (0..cs.len()).map(|i| wts[i] * cs[i][k]).sum::<f32>() / sum)
            };
            assert!(close(recoloured(&t, mix(old)), mix(&want), 1e-5));
        }
    }

    /// More species than an affine map of colours can tell apart: the least-squares fit,
    /// which is exact where the new colours are such a map of the old ones (here:
    /// channels swapped).
    #[test]
    fn recolouring_more_than_four_species_fits_an_affine_map() {
        let old = [CU, AG, O, [0.1, 0.6, 0.2], [0.3, 0.3, 0.9]];
        let swap = |c: [f32; 3]| [c[2], c[0], c[1]];
        let new: Vec<(usize, [f32; 3])> = old.iter().map(|&c| swap(c)).enumerate().collect();
        let t = recolour_of(&old, &new).unwrap();
        for c in old {
            assert!(close(recoloured(&t, c), swap(c), 1e-4), "{c:?}");
        }
        // How far the fit misses, for the summary: nothing here; much where one of five
        // species alone turns blue (no affine map does that).
        let file = species(&old);
        assert!(style_of(&new).recolour_miss(&file).unwrap() < 1e-4);
        let one = style_of(&[(1, [0.0, 0.0, 1.0])])
            .recolour_miss(&file)
            .unwrap();
        assert!(one > 0.05, "{one}");
        assert_eq!(style_of(&[]).recolour_miss(&file), None);
        let three = species(&old[..3]);
        // A hidden species is in no cluster drawn: the other four fit exactly.
        let mut hiding = style_of(&[(1, [0.0, 0.0, 1.0])]);
        hiding.species.push(SpeciesStyle {
            name: "s4".into(),
            hidden: true,
            ..Default::default()
        });
        assert!(hiding.recolour_miss(&file).unwrap() < 1e-4);
        assert!(
            style_of(&[(1, [0.0, 0.0, 1.0])])
                .recolour_miss(&three)
                .unwrap()
                < 1e-4
        );
        // Unchanged colours, or a colour map: nothing to recolour.
        assert_eq!(recolour_of(&old, &[(1, AG)]), None);
        let style = PointStyle {
            colour_map: Some(ColourMap::Viridis),
            species: vec![SpeciesStyle {
                name: "s0".into(),
                colour: Some([1.0, 0.0, 0.0]),
                ..Default::default()
            }],
            ..Default::default()
        };
        let file = species(&old);
        assert_eq!(
            style.cluster_recolour(&file, &style.species_table(&file).unwrap()),
            None
        );
    }

    #[test]
    fn colour_maps_run_from_their_first_to_their_last_stop() {
        for m in ColourMap::ALL {
            let s = m.stops();
            let lin = |c: [f32; 3]| c.map(crate::renderer::srgb_to_linear);
            let close = |a: [f32; 3], b: [f32; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-6);
            assert!(close(m.colour(0.0), lin(s[0])));
            assert!(close(m.colour(1.0), lin(s[s.len() - 1])));
            assert_eq!(m.colour(-3.0), m.colour(0.0));
            assert_eq!(m.colour(f32::NAN), m.colour(0.0));
            assert_eq!(ColourMap::from_name(m.name()), Some(m));
        }
        // Viridis, magma and cividis grow in lightness (and so print in grey).
        let luma = |c: [f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        for m in [ColourMap::Viridis, ColourMap::Magma, ColourMap::Cividis] {
            let l: Vec<f32> = (0..=64).map(|i| luma(m.colour(i as f32 / 64.0))).collect();
            assert!(l.windows(2).all(|w| w[1] > w[0]), "{} {l:?}", m.name());
        }
    }

    /// A shown range maps values from it, not from each file's own range: a frame whose
    /// values are ten times another's maps each value ten times further, and a constant
    /// attribute to its place in the range.
    #[test]
    fn a_shown_attribute_range_is_the_same_for_every_file() {
        let info = |min: f32, max: f32| mdlod_format::meta::AttributeInfo {
            name: "c_ke".into(),
            min,
            max,
            log10: false,
        };
        let range = Some([0.0, 8.0]);
        let cold = AttributeScale::with_range(&info(0.0367, 0.7203), range);
        let hot = AttributeScale::with_range(&info(0.367, 7.203), range);
        assert_eq!(cold.of_value(0.5), 0.0625);
        assert_eq!(hot.of_value(5.0), 0.625);
        assert_eq!(hot.of_value(9.0), 1.0);
        // Quantized particle values: the file's range, then the shown one.
        for q in [0u16, 1000, 65535] {
            let value = |i: &mdlod_format::meta::AttributeInfo| {
                f64::from(i.min) + f64::from(i.max - i.min) * f64::from(q) / 65535.0
            };
            let (c, h) = (value(&info(0.0367, 0.7203)), value(&info(0.367, 7.203)));
            assert!(
                (f64::from(cold.of_quantized(q)) - c / 8.0).abs() < 1e-6,
                "{q}"
            );
            assert!(
                (f64::from(hot.of_quantized(q)) - h / 8.0).abs() < 1e-6,
                "{q}"
            );
        }
        // Without a range, both span the whole map.
        let own = AttributeScale::new(&info(0.367, 7.203));
        assert_eq!((own.of_quantized(0), own.of_quantized(65535)), (0.0, 1.0));
        // A constant attribute at its value's place.
        let constant = AttributeScale::with_range(&info(2.0, 2.0), range);
        assert_eq!(
            (constant.of_value(2.0), constant.of_quantized(7)),
            (0.25, 0.25)
        );
        // Ranges that are none are refused.
        for bad in [
            [1.0, 1.0],
            [2.0, 1.0],
            [0.0, f32::INFINITY],
            [f32::NAN, 1.0],
        ] {
            let style = PointStyle {
                attribute_range: Some(bad),
                ..Default::default()
            };
            assert!(style.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn attribute_scales_map_ranges_linearly_and_constants_to_one() {
        let scale = |min: f32, max: f32| {
            AttributeScale::new(&mdlod_format::meta::AttributeInfo {
                name: "a".into(),
                min,
                max,
                log10: false,
            })
        };
        let s = scale(-2.0, 2.0);
        assert!(!s.is_constant());
        assert_eq!(
            (s.of_value(0.0), s.of_value(-5.0), s.of_value(3.0)),
            (0.5, 0.0, 1.0)
        );
        assert_eq!((s.of_quantized(0), s.of_quantized(65535)), (0.0, 1.0));
        assert_eq!(s.of_value(f32::NAN), 0.0);
        let m = 2.5e-6f32;
        for c in [
            scale(m, m),
            scale(m, f32::from_bits(m.to_bits() + 3)),
            scale(0.0, 0.0),
        ] {
            assert!(c.is_constant(), "{c:?}");
            assert_eq!(
                (c.of_value(m), c.of_value(-1.0), c.of_quantized(0)),
                (1.0, 1.0, 1.0)
            );
        }
        assert!(!scale(m, m * 1.001).is_constant());
        // Ends whose difference overflows single precision.
        let wide = scale(-f32::MAX, f32::MAX);
        assert!(!wide.is_constant());
        assert_eq!(wide.of_value(0.0), 0.5);
    }

    #[test]
    fn cool_warm_follows_morelands_map_without_kinks() {
        // Moreland's smooth diverging map (as matplotlib's coolwarm draws it), in 8-bit
        // sRGB, at every eighth of the way: within a level of each. (The five stops
        // drawn before were up to 18 levels off between the quarters.)
        let srgb = |t: f32| {
            ColourMap::CoolWarm
                .colour(t)
                .map(|c| (crate::renderer::linear_to_srgb(c) * 255.0).round() as i32)
        };
        for (t, want) in [
            (0.0, [59, 76, 192]),
            (0.125, [98, 130, 234]),
            (0.25, [141, 176, 254]),
            (0.375, [184, 208, 249]),
            (0.5, [221, 221, 221]),
            (0.625, [245, 196, 173]),
            (0.75, [244, 154, 123]),
            (0.875, [222, 97, 76]),
            (1.0, [180, 4, 38]),
        ] {
            let got = srgb(t);
            assert!(
                (0..3).all(|k| (got[k] - want[k]).abs() <= 1),
                "{t}: {got:?} against {want:?}"
            );
        }
    }

    #[test]
    fn viridis_and_magma_follow_matplotlibs() {
        // Matplotlib's maps in 8-bit sRGB between their samples here: within 3 levels
        // (the 11 stops before were 4-13 off at these points).
        for (map, points) in [
            (
                ColourMap::Viridis,
                [
                    (0.05, [71, 19, 101]),
                    (0.25, [59, 82, 139]),
                    (0.65, [47, 180, 124]),
                    (0.95, [223, 227, 24]),
                ],
            ),
            (
                ColourMap::Magma,
                [
                    (0.05, [6, 5, 26]),
                    (0.25, [81, 18, 124]),
                    (0.65, [237, 90, 95]),
                    (0.95, [253, 231, 169]),
                ],
            ),
        ] {
            for (t, want) in points {
                let got = map
                    .colour(t)
                    .map(|c| (crate::renderer::linear_to_srgb(c) * 255.0).round() as i32);
                assert!(
                    (0..3).all(|k| (got[k] - want[k]).abs() <= 3),
                    "{map:?} at {t}: {got:?} against {want:?}"
                );
            }
        }
    }

    #[test]
    fn the_species_table_takes_overrides_scale_and_hiding() {
        let sp = |name: &str, r: f32| mdlod_format::meta::Species {
            name: name.into(),
            radius: r,
            colour: [0.5, 0.5, 0.5],
            radius_range: None,
        };
        let style = PointStyle {
            species: vec![
                SpeciesStyle {
                    name: "A".into(),
                    colour: Some([1.0, 0.0, 0.0]),
                    radius: None,
                    hidden: false,
                },
                SpeciesStyle {
                    name: "B".into(),
                    hidden: true,
                    ..Default::default()
                },
            ],
            radius_scale: 2.0,
            colour_map: None,
            palette: Palette::Default,
            attribute: None,
            attribute_range: None,
            range_derived: false,
            log_scale: false,
            clip: vec![],
            hidden_values: vec![],
            hide_by: None,
            hidden_named: vec![],
        };
        let file = [sp("A", 1.0), sp("B", 1.5), sp("C", 0.5)];
        let t = style.species_table(&file).unwrap();
        assert_eq!(
            t,
            vec![
                [1.0, 0.0, 0.0, 2.0],
                [0.5, 0.5, 0.5, 0.0],
                [0.5, 0.5, 0.5, 1.0]
            ]
        );
        let err = style.species_table(&file[1..]).unwrap_err();
        assert!(err.contains("\"A\"") && err.contains("B, C"), "{err}");
        assert!(style.changes_geometry());
        assert!(!PointStyle::default().changes_geometry());
        // Hiding changes no size.
        let hiding = PointStyle {
            species: vec![SpeciesStyle {
                name: "B".into(),
                hidden: true,
                ..Default::default()
            }],
            hidden_values: vec![[0.5, 1.5]],
            ..Default::default()
        };
        assert!(!hiding.changes_geometry());
        assert!(PointStyle {
            radius_scale: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
    }

    /// sRGB in f64, the reference the packing's tables must agree with.
    fn srgb(v: f64) -> f64 {
        if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        }
    }

    /// Colours go to the GPU as the nearest sRGB byte of each channel (R in the low
    /// byte, alpha 255), clamped, NaN as 0; they come back as that byte's light, so a
    /// round trip stays within half an sRGB level everywhere, dark colours included.
    #[test]
    fn colours_are_packed_as_the_nearest_srgb_byte_and_unpacked_as_its_light() {
        // Byte 128 is linear 0.2159 (linear packing gave it byte 55).
        assert_eq!(pack_colour([1.0, 0.0, 0.2159]), 0xff80_00ff);
        assert_eq!(pack_colour([2.0, -1.0, f32::NAN]), 0xff00_00ff);
        let mut v = 0.0f32;
        while v <= 1.0 {
            let want = srgb(f64::from(v)) * 255.0;
            let got = pack_colour([v, v, v]);
            let b = f64::from(got & 0xff);
            // Ties within rounding either way.
            assert!((b - want).abs() <= 0.5 + 1e-4, "{v}: byte {b}, sRGB {want}");
            assert_eq!(got, (b as u32 * 0x0001_0101) | 0xff00_0000);
            let back = unpack_colour(got)[0];
            assert!(
                (srgb(f64::from(back)) * 255.0 - want).abs() <= 0.5 + 1e-4,
                "{v}: back {back}"
            );
            v += 1.0 / 65536.0 + v * 1e-3;
        }
        // Every byte's light packs back to that byte.
        for k in 0..=255u32 {
            let c = k | (k << 8) | (k << 16) | 0xff00_0000;
            assert_eq!(pack_colour(unpack_colour(c)), c, "byte {k}");
        }
        // magma's dark end: sRGB (0, 0, 4) and (0, 0, 4 + ...) keep their levels.
        let dark = ColourMap::Magma.colour(0.0);
        let p = pack_colour(dark).to_le_bytes();
        for c in 0..3 {
            let want = srgb(f64::from(dark[c])) * 255.0;
            assert!(
                (f64::from(p[c]) - want).abs() <= 0.5 + 1e-4,
                "{dark:?} {p:?}"
            );
        }
    }

    /// The file's node colours (linear bytes) go to the GPU as the nearest sRGB byte of
    /// their light: what packing their linear colour gives.
    #[test]
    fn file_colours_are_repacked_as_srgb() {
        for k in 0..=255u32 {
            let c = k | ((255 - k) << 8) | ((k / 3) << 16) | 0xff00_0000;
            let light = [k, 255 - k, k / 3].map(|b| b as f32 / 255.0);
            assert_eq!(pack_file_colour(c), pack_colour(light), "byte {k}");
        }
        // Alpha is always opaque, as the file's.
        assert_eq!(pack_file_colour(0) >> 24, 255);
    }
}
