//! The format's words: its keywords, and each field's name as the
//! messages say it.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Keyword {
    Near,
    Left,
    Right,
    Bottom,
    Top,
    Res,
    Sphere,
    Light,
    Back,
    Ambient,
    Output,
}

impl Keyword {
    const ALL: [Keyword; 11] = [
        Keyword::Near,
        Keyword::Left,
        Keyword::Right,
        Keyword::Bottom,
        Keyword::Top,
        Keyword::Res,
        Keyword::Sphere,
        Keyword::Light,
        Keyword::Back,
        Keyword::Ambient,
        Keyword::Output,
    ];

    pub(super) fn name(self) -> &'static str {
        match self {
            Keyword::Near => "NEAR",
            Keyword::Left => "LEFT",
            Keyword::Right => "RIGHT",
            Keyword::Bottom => "BOTTOM",
            Keyword::Top => "TOP",
            Keyword::Res => "RES",
            Keyword::Sphere => "SPHERE",
            Keyword::Light => "LIGHT",
            Keyword::Back => "BACK",
            Keyword::Ambient => "AMBIENT",
            Keyword::Output => "OUTPUT",
        }
    }

    pub(super) fn from_token(token: &[u8]) -> Option<Keyword> {
        Keyword::ALL
            .into_iter()
            .find(|k| k.name().as_bytes().eq_ignore_ascii_case(token))
    }

    /// The keyword `token` is most likely a misspelling of: the nearest by
    /// edit distance (a swap of two neighbours counts one, as in `BAKC`),
    /// if at most a third of its letters (and at least one) are off.
    pub(super) fn nearest(token: &str) -> Option<Keyword> {
        let token = token.to_ascii_uppercase();
        let allowed = (token.chars().count() / 3).max(1);
        Keyword::ALL
            .into_iter()
            .map(|k| (strsim::osa_distance(&token, k.name()), k))
            .filter(|&(distance, _)| distance <= allowed)
            .min_by_key(|&(distance, _)| distance)
            .map(|(_, k)| k)
    }

    /// A line that gives this directive, for the message when it is missing.
    pub(super) fn example(self) -> &'static str {
        match self {
            Keyword::Near => "NEAR 1",
            Keyword::Left => "LEFT -1",
            Keyword::Right => "RIGHT 1",
            Keyword::Bottom => "BOTTOM -1",
            Keyword::Top => "TOP 1",
            Keyword::Res => "RES 512 512",
            Keyword::Sphere => "SPHERE ball 0 0 -10 1 1 1 1 0 0 0.2 0.8 0.5 0 50",
            Keyword::Light => "LIGHT sun 0 10 0 1 1 1",
            Keyword::Back => "BACK 0 0 0",
            Keyword::Ambient => "AMBIENT 0.2 0.2 0.2",
            Keyword::Output => "OUTPUT image.png",
        }
    }
}

/// The sphere's fields in words, in the classic dialect's order (the
/// browser dialect swaps the exponent and the reflectivity, see `scene::parse`).
pub(super) const SPHERE_FIELDS: [&str; 16] = [
    "the sphere's x position",
    "the sphere's y position",
    "the sphere's z position",
    "the sphere's x scale",
    "the sphere's y scale",
    "the sphere's z scale",
    "the sphere's red component",
    "the sphere's green component",
    "the sphere's blue component",
    "the sphere's ambient coefficient",
    "the sphere's diffuse coefficient",
    "the sphere's specular coefficient",
    "the sphere's reflectivity",
    "the sphere's specular exponent",
    "the sphere's refractivity",
    "the sphere's index of refraction",
];
pub(super) const LIGHT_FIELDS: [&str; 6] = [
    "the light's x position",
    "the light's y position",
    "the light's z position",
    "the light's red intensity",
    "the light's green intensity",
    "the light's blue intensity",
];
pub(super) const BACK_FIELDS: [&str; 3] = [
    "the background's red component",
    "the background's green component",
    "the background's blue component",
];
pub(super) const AMBIENT_FIELDS: [&str; 3] = [
    "the ambient light's red intensity",
    "the ambient light's green intensity",
    "the ambient light's blue intensity",
];
/// NEAR's value, in words.
pub(super) const NEAR_FIELD: &str = "the distance to the image plane (NEAR)";

/// The name of the image plane edge that `keyword` (LEFT, RIGHT, BOTTOM or TOP) gives.
pub(super) fn extent_field(keyword: Keyword) -> &'static str {
    match keyword {
        Keyword::Left => "the left edge of the image plane",
        Keyword::Right => "the right edge of the image plane",
        Keyword::Bottom => "the bottom edge of the image plane",
        _ => "the top edge of the image plane",
    }
}

/// RES's first number, in words.
pub const COLUMNS_FIELD: &str = "the number of columns";
/// RES's second number, in words.
pub const ROWS_FIELD: &str = "the number of rows";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misspelt_keywords_get_the_nearest_one() {
        let nearest = |token| Keyword::nearest(token).map(Keyword::name);
        assert_eq!(nearest("BAKC"), Some("BACK"), "a swap counts one");
        assert_eq!(nearest("spheres"), Some("SPHERE"));
        assert_eq!(nearest("AMBIANT"), Some("AMBIENT"));
        assert_eq!(nearest("OUTPUTT"), Some("OUTPUT"));
        assert_eq!(nearest("RE"), Some("RES"));
        assert_eq!(nearest("CAMERA"), None);
        assert_eq!(nearest("X"), None);
        assert_eq!(nearest("--------------------------a6abca43715a41"), None);
    }
}
