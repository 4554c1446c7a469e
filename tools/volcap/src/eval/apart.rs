//! `volcap eval --drop-apart`: the pieces-apart pass's gaps, as the product runs it by
//! default (`volcap_engine::pieces`).

/// `--drop-apart`: the gaps across and in depth, or none (`off`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Apart(pub Option<[f32; 2]>);

impl Apart {
    /// The product's: [`volcap_engine::pieces::DEFAULT_GAP`] on every axis.
    pub const PRODUCT: Apart = Apart(Some([volcap_engine::pieces::DEFAULT_GAP; 2]));

    /// The model label's suffix (none for the product's setting).
    pub fn label(&self) -> String {
        match *self {
            d if d == Apart::PRODUCT => String::new(),
            Apart(Some(g)) => format!("-apart{}x{}", g[0], g[1]),
            Apart(None) => "-keep-apart".into(),
        }
    }
}

pub(super) fn parse_apart(s: &str) -> Result<Apart, String> {
    if s == "off" {
        return Ok(Apart(None));
    }
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    match v[..] {
        [xy, z] if [xy, z].iter().all(|g| (0.0..=1.0).contains(g)) => Ok(Apart(Some([xy, z]))),
        _ => Err(format!(
            "{s:?}: XY,Z, each a fraction of the grid's side in [0, 1], or off"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The product's setting, `off`, a setting of two gaps; anything else refused by name.
    #[test]
    fn parses_and_labels() {
        assert_eq!(parse_apart("0.1,0.1"), Ok(Apart::PRODUCT));
        assert_eq!(Apart::PRODUCT.label(), "");
        assert_eq!(parse_apart("off"), Ok(Apart(None)));
        assert_eq!(Apart(None).label(), "-keep-apart");
        assert_eq!(parse_apart("0.07, 0.04"), Ok(Apart(Some([0.07, 0.04]))));
        assert_eq!(Apart(Some([0.07, 0.04])).label(), "-apart0.07x0.04");
        for bad in ["0.1", "0.1,0.1,0.1", "1.5,0.1", "-0.1,0.1", "x,0.1", ""] {
            let e = parse_apart(bad).unwrap_err();
            assert!(e.contains(&format!("{bad:?}")), "{bad}: {e}");
        }
    }
}
