//! `terawalk build --generate SPEC`: a procedural scene fed straight into the build, so that a
//! 10^9-triangle scene needs no 40 GB model file. SPEC is `plant:COUNT` or `assembly:COUNT`,
//! with `,seed=N` and, for the assembly, `,one-object`; the scene is the one `terawalk
//! generate` writes for the same kind, count, seed and `--one-object`.

use std::fmt;

use tw_io::generate::{AssemblyObjects, AssemblyParams, AssemblySource, PlantParams, PlantSource};
use tw_io::TriangleSource;

use crate::units::parse_count;

/// Which generator, and for the assembly how its objects are cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeneratedKind {
    Plant,
    /// `one_object`: everything as one object (`generate assembly --one-object`).
    Assembly {
        one_object: bool,
    },
}

/// A parsed `--generate` value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GenerateSpec {
    pub kind: GeneratedKind,
    pub triangles: u64,
    pub seed: u64,
}

/// The seed when SPEC names none: `terawalk generate`'s default.
const DEFAULT_SEED: u64 = 1;

const FORM: &str = "expected plant:COUNT or assembly:COUNT, optionally followed by ,seed=N \
                    (and ,one-object for an assembly), e.g. plant:1G or assembly:10M,seed=3";

impl GenerateSpec {
    /// The generator, streaming as the build reads it.
    pub fn source(&self) -> Result<Box<dyn TriangleSource>, tw_io::ImportError> {
        let (triangles, seed) = (self.triangles, self.seed);
        Ok(match self.kind {
            GeneratedKind::Plant => Box::new(PlantSource::new(PlantParams { triangles, seed })?),
            GeneratedKind::Assembly { one_object } => {
                let objects = if one_object { AssemblyObjects::One } else { AssemblyObjects::PerPart };
                Box::new(AssemblySource::new(AssemblyParams { triangles, seed, objects })?)
            }
        })
    }

    /// The units of the generator's coordinates, recorded in the store unless `--units` says
    /// otherwise: the plant is modelled in metres, the assembly in millimetres.
    pub fn units(&self) -> &'static str {
        match self.kind {
            GeneratedKind::Plant => "m",
            GeneratedKind::Assembly { .. } => "mm",
        }
    }
}

/// The canonical form of the spec (`plant:1000000000,seed=1`), for messages.
impl fmt::Display for GenerateSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.kind {
            GeneratedKind::Plant => write!(f, "plant:{},seed={}", self.triangles, self.seed),
            GeneratedKind::Assembly { one_object } => {
                write!(f, "assembly:{},seed={}", self.triangles, self.seed)?;
                if one_object {
                    write!(f, ",one-object")?;
                }
                Ok(())
            }
        }
    }
}

/// Parses `--generate`'s value (clap's value parser): the form, the count (as `generate
/// --triangles`: 1G, 1e9, 10^9, 100M) and the generator's own range, so that a bad value is
/// refused before any work.
pub fn parse_generate_spec(s: &str) -> Result<GenerateSpec, String> {
    let mut parts = s.trim().split(',').map(str::trim);
    let head = parts.next().unwrap_or_default();
    let (kind, count) = head.split_once(':').ok_or_else(|| format!("`{s}`: {FORM}"))?;
    let triangles = parse_count(count).map_err(|e| format!("`{s}`: {e}"))?;
    let mut spec = GenerateSpec { kind: parse_kind(kind, s)?, triangles, seed: DEFAULT_SEED };
    let mut seen = Vec::new();
    for option in parts {
        let name = option.split_once('=').map_or(option, |(n, _)| n.trim());
        if seen.contains(&name) {
            return Err(format!("`{s}`: {name} is given twice"));
        }
        seen.push(name);
        apply_option(&mut spec, option, s)?;
    }
    spec.source().map_err(|e| format!("`{s}`: {e}"))?;
    Ok(spec)
}

/// The generator's name before the `:`.
fn parse_kind(kind: &str, whole: &str) -> Result<GeneratedKind, String> {
    match kind.trim() {
        "plant" => Ok(GeneratedKind::Plant),
        "assembly" => Ok(GeneratedKind::Assembly { one_object: false }),
        other => Err(format!("`{whole}`: unknown generator `{other}`; {FORM}")),
    }
}

/// One `,option` after the count: `seed=N` or, for the assembly, `one-object`.
fn apply_option(spec: &mut GenerateSpec, option: &str, whole: &str) -> Result<(), String> {
    match option.split_once('=').map(|(n, v)| (n.trim(), v.trim())) {
        Some(("seed", v)) => {
            spec.seed =
                v.parse().map_err(|_| format!("`{whole}`: seed must be a whole number ≥ 0, not `{v}`"))?;
        }
        None if option == "one-object" => match &mut spec.kind {
            GeneratedKind::Assembly { one_object } => *one_object = true,
            GeneratedKind::Plant => return Err(format!("`{whole}`: one-object applies to assembly only")),
        },
        _ => return Err(format!("`{whole}`: unknown option `{option}`; {FORM}")),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(kind: GeneratedKind, triangles: u64, seed: u64) -> GenerateSpec {
        GenerateSpec { kind, triangles, seed }
    }

    #[test]
    fn counts_seeds_and_options() {
        let one = GeneratedKind::Assembly { one_object: true };
        assert_eq!(parse_generate_spec("plant:1G"), Ok(spec(GeneratedKind::Plant, 1_000_000_000, 1)));
        assert_eq!(
            parse_generate_spec("plant:10^9,seed=7"),
            Ok(spec(GeneratedKind::Plant, 1_000_000_000, 7))
        );
        assert_eq!(parse_generate_spec("plant:1e6"), Ok(spec(GeneratedKind::Plant, 1_000_000, 1)));
        assert_eq!(parse_generate_spec("assembly:100M,one-object,seed=2"), Ok(spec(one, 100_000_000, 2)));
        assert_eq!(parse_generate_spec(" assembly:200k, one-object "), Ok(spec(one, 200_000, 1)));
        assert_eq!(
            parse_generate_spec("assembly:200k,seed=5").unwrap().to_string(),
            "assembly:200000,seed=5"
        );
    }

    #[test]
    fn bad_values_say_what_is_wrong() {
        let err = |s: &str| parse_generate_spec(s).unwrap_err();
        assert!(err("plant").contains("expected plant:COUNT"), "{}", err("plant"));
        assert!(err("tree:1M").contains("unknown generator `tree`"));
        assert!(err("plant:lots").contains("not a count"));
        assert!(err("plant:1M,seed=-1").contains("seed must be"));
        assert!(err("plant:1M,seed=1,seed=2").contains("seed is given twice"));
        assert!(err("plant:1M,one-object").contains("assembly only"));
        assert!(err("plant:1M,colour=red").contains("unknown option `colour=red`"));
        // The generators' own ranges: refused while parsing, before any work.
        assert!(err("plant:10").contains("generated plant"), "{}", err("plant:10"));
        assert!(err("plant:10^12").contains("generated plant"), "{}", err("plant:10^12"));
    }

    #[test]
    fn units_follow_the_generator() {
        assert_eq!(parse_generate_spec("plant:1M").unwrap().units(), "m");
        assert_eq!(parse_generate_spec("assembly:1M").unwrap().units(), "mm");
    }
}
