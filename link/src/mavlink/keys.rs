//! MAVLink 2 signing keys on disk: one file per key holding 64 hexadecimal digits, in a directory
//! outside any repository (`$GCS_KEY_DIR`, else `$XDG_CONFIG_HOME/gcs/keys`, else
//! `~/.config/gcs/keys`), readable by its owner only. A key file anyone else may read is refused,
//! as ssh refuses such a private key.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use ::mavlink::dialects::ardupilotmega::{MavMessage, SETUP_SIGNING_DATA};

use super::link::SigningKey;

/// Why a key could not be made, found or read.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    /// Neither `$GCS_KEY_DIR`, `$XDG_CONFIG_HOME` nor `$HOME` is set.
    #[error("no place for signing keys: set GCS_KEY_DIR (or HOME)")]
    NoHome,
    /// A key name that is not a plain file name.
    #[error("key name {0:?}: use letters, digits, '-' and '_' only")]
    BadName(String),
    /// Creating a key that exists.
    #[error("{0} exists: a key is never overwritten (remove it first if you mean to)")]
    Exists(PathBuf),
    /// No such key.
    #[error("no signing key {name:?} in {dir} (make one with: gcs key new {name})")]
    Missing {
        /// The name asked for.
        name: String,
        /// Where it was looked for.
        dir: PathBuf,
    },
    /// The file or its directory may be read by others.
    #[error("{path} may be read by others (mode {mode:03o}): run chmod {want:03o} {path}")]
    Permissions {
        /// The file or directory.
        path: PathBuf,
        /// Its permission bits.
        mode: u32,
        /// What they should be.
        want: u32,
    },
    /// Not 64 hexadecimal digits.
    #[error("{path}: {why}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// The file system refused.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> KeyError + '_ {
    move |source| KeyError::Io {
        path: path.to_owned(),
        source,
    }
}

/// A directory of signing keys.
#[derive(Debug, Clone)]
pub struct KeyStore {
    dir: PathBuf,
}

impl KeyStore {
    /// The store at `dir`.
    pub fn at(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The user's store: `$GCS_KEY_DIR`, else `$XDG_CONFIG_HOME/gcs/keys`, else
    /// `~/.config/gcs/keys`.
    pub fn user() -> Result<Self, KeyError> {
        let var = |name| std::env::var_os(name).filter(|v| !v.is_empty());
        let dir = if let Some(dir) = var("GCS_KEY_DIR") {
            PathBuf::from(dir)
        } else if let Some(config) = var("XDG_CONFIG_HOME") {
            PathBuf::from(config).join("gcs/keys")
        } else {
            PathBuf::from(var("HOME").ok_or(KeyError::NoHome)?).join(".config/gcs/keys")
        };
        Ok(Self::at(dir))
    }

    /// The store's directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The file of the key `name`.
    pub fn path(&self, name: &str) -> Result<PathBuf, KeyError> {
        let plain = !name.is_empty()
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
        if !plain {
            return Err(KeyError::BadName(name.into()));
        }
        Ok(self.dir.join(format!("{name}.key")))
    }

    /// Makes a new random key `name` (the directory is made owner-only, the file owner-read-write
    /// only) and returns its file.
    pub fn create(&self, name: &str) -> Result<PathBuf, KeyError> {
        let path = self.path(name)?;
        make_private_dir(&self.dir)?;
        if path.exists() {
            return Err(KeyError::Exists(path));
        }
        let mut secret = [0u8; 32];
        std::fs::File::open("/dev/urandom")
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut secret))
            .map_err(io(Path::new("/dev/urandom")))?;
        write_key_file(&path, &secret)?;
        Ok(path)
    }

    /// The names of the keys in the store.
    pub fn list(&self) -> Result<Vec<String>, KeyError> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(vec![]),
            Err(e) => return Err(io(&self.dir)(e)),
        };
        let mut names: Vec<String> = entries
            .filter_map(Result::ok)
            .filter_map(|e| {
                e.file_name()
                    .to_str()
                    .and_then(|n| n.strip_suffix(".key"))
                    .map(str::to_owned)
            })
            .collect();
        names.sort();
        Ok(names)
    }

    /// Reads a key: a name in the store, or the path of a key file (anything with a `/`).
    pub fn load(&self, name_or_path: &str) -> Result<SigningKey, KeyError> {
        if name_or_path.contains('/') {
            return read_key_file(Path::new(name_or_path));
        }
        let path = self.path(name_or_path)?;
        if !path.exists() {
            return Err(KeyError::Missing {
                name: name_or_path.into(),
                dir: self.dir.clone(),
            });
        }
        read_key_file(&path)
    }
}

/// Refuses `path` if anyone but its owner may read, write or enter it (`want`: the mode to
/// suggest).
#[cfg(unix)]
fn owner_only(path: &Path, want: u32) -> Result<(), KeyError> {
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(path)
        .map_err(io(path))?
        .permissions()
        .mode()
        & 0o777;
    if mode & 0o077 != 0 {
        return Err(KeyError::Permissions {
            path: path.into(),
            mode,
            want,
        });
    }
    Ok(())
}

/// Makes `dir` (and its parents) and refuses it if others may enter it.
fn make_private_dir(dir: &Path) -> Result<(), KeyError> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::DirBuilderExt;
        if !dir.exists() {
            std::fs::DirBuilder::new()
                .recursive(true)
                .mode(0o700)
                .create(dir)
                .map_err(io(dir))?;
        }
        owner_only(dir, 0o700)?;
    }
    #[cfg(not(unix))]
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    Ok(())
}

/// Writes a new key file readable and writable by its owner only; never overwrites.
pub fn write_key_file(path: &Path, secret: &[u8; 32]) -> Result<(), KeyError> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
    let mut file = options.open(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            KeyError::Exists(path.into())
        } else {
            io(path)(e)
        }
    })?;
    let hex: String = secret.iter().map(|b| format!("{b:02x}")).collect();
    file.write_all(format!("{hex}\n").as_bytes())
        .and_then(|()| file.sync_all())
        .map_err(io(path))
}

/// Reads a key file: 64 hexadecimal digits, readable by its owner only.
pub fn read_key_file(path: &Path) -> Result<SigningKey, KeyError> {
    #[cfg(unix)]
    owner_only(path, 0o600)?;
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    SigningKey::from_hex(&text).map_err(|why| KeyError::Malformed {
        path: path.into(),
        why,
    })
}

/// Now as a MAVLink signing timestamp: units of 10 µs since 2015-01-01 00:00 UTC.
pub fn signing_timestamp_now() -> u64 {
    const EPOCH_2015_S: u64 = 1_420_070_400;
    let since_1970 = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros());
    u64::try_from(since_1970 / 10)
        .unwrap_or(u64::MAX)
        .saturating_sub(EPOCH_2015_S * 100_000)
}

/// The `SETUP_SIGNING` message that gives `key` to vehicle `target_system` (0: every vehicle on
/// the link).
pub fn setup_signing(key: &SigningKey, target_system: u8) -> MavMessage {
    MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
        initial_timestamp: signing_timestamp_now(),
        target_system,
        target_component: 0,
        secret_key: key.secret,
    })
}

/// The `SETUP_SIGNING` message that turns signing off on vehicle `target_system` (an all-zero
/// key; it must be signed with the vehicle's current key).
pub fn disable_signing(target_system: u8) -> MavMessage {
    MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
        initial_timestamp: 0,
        target_system,
        target_component: 0,
        secret_key: [0; 32],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scratch directory, removed when dropped.
    struct Scratch(std::path::PathBuf);

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn temp_store(tag: &str) -> (Scratch, KeyStore) {
        let dir = std::env::temp_dir().join(format!("gcs-keys-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let store = KeyStore::at(dir.join("keys"));
        (Scratch(dir), store)
    }

    #[test]
    fn a_new_key_is_private_random_and_never_overwritten() {
        let (_scratch, store) = temp_store("new");
        let a = store.create("alpha").expect("create");
        let b = store.create("beta").expect("create");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&a), 0o600);
            assert_eq!(mode(store.dir()), 0o700);
        }
        let (ka, kb) = (store.load("alpha").unwrap(), store.load("beta").unwrap());
        assert_ne!(ka.secret, kb.secret);
        assert_ne!(ka.secret, [0; 32]);
        assert_eq!(store.load(b.to_str().unwrap()).unwrap().secret, kb.secret);
        assert_eq!(store.list().unwrap(), ["alpha", "beta"]);
        let before = std::fs::read(&a).unwrap();
        assert!(matches!(store.create("alpha"), Err(KeyError::Exists(_))));
        assert_eq!(std::fs::read(&a).unwrap(), before);
    }

    #[test]
    fn keys_others_may_read_or_bad_names_are_refused_with_what_to_do() {
        let (_scratch, store) = temp_store("perm");
        let path = store.create("alpha").expect("create");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
            let e = store.load("alpha").unwrap_err().to_string();
            assert!(
                e.contains("may be read by others") && e.contains("chmod 600"),
                "{e}"
            );
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
            std::fs::set_permissions(store.dir(), std::fs::Permissions::from_mode(0o755)).unwrap();
            let e = store.create("beta").unwrap_err().to_string();
            assert!(e.contains("chmod 700"), "{e}");
        }
        for bad in ["", "../x", "a b", "a/b"] {
            assert!(
                matches!(store.path(bad), Err(KeyError::BadName(_))),
                "{bad}"
            );
        }
        let e = store.load("nobody").unwrap_err().to_string();
        assert!(e.contains("gcs key new nobody"), "{e}");
        let junk = store.dir().join("junk.key");
        write_key_file(&junk, &[7; 32]).unwrap();
        std::fs::write(&junk, "not hex\n").unwrap();
        let e = store.load("junk").unwrap_err().to_string();
        assert!(e.contains("64 hexadecimal digits"), "{e}");
    }

    #[test]
    fn timestamps_count_ten_microseconds_since_2015() {
        let t = signing_timestamp_now();
        // 2026 is about 11.9 years after 2015: 3.7e13 units of 10 µs.
        assert!(t > 30_000_000_000_000 && t < 100_000_000_000_000, "{t}");
    }
}
