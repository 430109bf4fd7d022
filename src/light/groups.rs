//! Light groups: the `lg_<name>` AOV each light's contributions go to. A light belongs to
//! the first group whose members match the name of the emitter it comes from (instance,
//! shape, punctual light, or `environment`): the request's groups first (`--light-group
//! key=pattern,…`, with `*` and `?` wildcards), then the scene's (glTF node `extras`);
//! lights in no group go to `default`.

use crate::scene::LightGroup;

/// The group a light falls in when no group names it.
pub const DEFAULT_GROUP: &str = "default";

/// The groups of a render and the group of each light.
#[derive(Clone, Debug, PartialEq)]
pub struct LightGroups {
    /// Group names, in layer order.
    pub names: Vec<String>,
    /// For each light, the index of its group in `names`.
    pub of_light: Vec<u32>,
}

impl LightGroups {
    /// Assigns the lights whose emitters are `light_names` to the `requested` groups (member
    /// patterns), then the `declared` ones (exact names), then [`DEFAULT_GROUP`] (a layer
    /// only if some light is left over, or no group was given at all).
    pub fn assign(
        light_names: &[String],
        requested: &[LightGroup],
        declared: &[LightGroup],
    ) -> Self {
        let mut names: Vec<String> = Vec::new();
        for g in requested.iter().chain(declared) {
            if !names.contains(&g.name) {
                names.push(g.name.clone());
            }
        }
        let index = |name: &str| names.iter().position(|n| n == name).expect("listed") as u32;
        let mut of_light = Vec::with_capacity(light_names.len());
        let mut leftover = false;
        for light in light_names {
            let group = requested
                .iter()
                .find(|g| g.members.iter().any(|p| glob(p, light)))
                .or_else(|| {
                    declared
                        .iter()
                        .find(|g| g.members.iter().any(|m| m == light))
                });
            match group {
                Some(g) => of_light.push(index(&g.name)),
                None => {
                    leftover = true;
                    of_light.push(u32::MAX);
                }
            }
        }
        if leftover || names.is_empty() {
            let default = match names.iter().position(|n| n == DEFAULT_GROUP) {
                Some(i) => i as u32,
                None => {
                    names.push(DEFAULT_GROUP.into());
                    names.len() as u32 - 1
                }
            };
            for g in &mut of_light {
                if *g == u32::MAX {
                    *g = default;
                }
            }
        }
        Self { names, of_light }
    }
}

/// Parses `key=pattern,pattern;key2=pattern`: light groups of a request.
pub fn parse(text: &str) -> Result<Vec<LightGroup>, String> {
    let mut groups: Vec<LightGroup> = Vec::new();
    for item in text.split(';').map(str::trim).filter(|s| !s.is_empty()) {
        let (name, patterns) = item
            .split_once('=')
            .ok_or_else(|| format!("{item:?}: expected NAME=PATTERN[,PATTERN...]"))?;
        let name = name.trim().to_ascii_lowercase();
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(format!(
                "{name:?}: a light group name is letters, digits and _"
            ));
        }
        let members: Vec<String> = patterns
            .split(',')
            .map(str::trim)
            .filter(|p| !p.is_empty())
            .map(str::to_string)
            .collect();
        if members.is_empty() {
            return Err(format!("light group {name:?} has no pattern"));
        }
        match groups.iter_mut().find(|g| g.name == name) {
            Some(g) => g.members.extend(members),
            None => groups.push(LightGroup { name, members }),
        }
    }
    Ok(groups)
}

/// `key=pattern,pattern;…`, as [`parse`] reads it.
pub fn describe(groups: &[LightGroup]) -> String {
    groups
        .iter()
        .map(|g| format!("{}={}", g.name, g.members.join(",")))
        .collect::<Vec<_>>()
        .join(";")
}

/// Whether `name` matches `pattern`, where `*` stands for any run of characters and `?`
/// for one.
pub fn glob(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    // Iterative matching with backtracking to the last `*`.
    let (mut i, mut j) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while j < n.len() {
        if i < p.len() && (p[i] == '?' || p[i] == n[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some((i, j));
            i += 1;
        } else if let Some((si, sj)) = star {
            i = si + 1;
            j = sj + 1;
            star = Some((si, sj + 1));
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_match_like_shell_globs() {
        assert!(glob("key*", "key_light"));
        assert!(glob("*light", "key_light"));
        assert!(glob("k?y*t", "key_light"));
        assert!(glob("*", ""));
        assert!(!glob("key", "key_light"));
        assert!(!glob("?", ""));
        assert!(glob("a*b*c", "aXbYbZc"));
    }

    #[test]
    fn lights_go_to_the_first_matching_group_or_default() {
        let names: Vec<String> = ["key", "fill", "lamp_1", "environment"]
            .map(String::from)
            .to_vec();
        let requested = parse("warm=lamp_*;sky=environment").unwrap();
        let declared = vec![LightGroup {
            name: "keys".into(),
            members: vec!["key".into(), "lamp_1".into()],
        }];
        let groups = LightGroups::assign(&names, &requested, &declared);
        assert_eq!(groups.names, ["warm", "sky", "keys", "default"]);
        assert_eq!(groups.of_light, [2, 3, 0, 1]);
        // No groups at all: everything in default.
        let all = LightGroups::assign(&names, &[], &[]);
        assert_eq!((all.names.len(), all.of_light), (1, vec![0; 4]));
        assert!(parse("bad name=x").is_err() && parse("x=").is_err());
        assert_eq!(describe(&requested), "warm=lamp_*;sky=environment");
    }
}
