//! iceoryx2 settings, the node, and service creation with the pipeline's QoS.

use iceoryx2::config::Config;
use iceoryx2::node::{Node, NodeBuilder};
use iceoryx2::prelude::{FileName, NodeName, Path, SemanticString, ServiceName};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as StaticPattern;
use teleop_msgs::{Message, SERVICE_PREFIX};
use teleop_namespace::{qualified, Namespace};

use crate::ports::{Publisher, Subscriber};
use crate::Service;

/// Environment variable with the iceoryx2 root path (a directory).
pub const ENV_IPC_ROOT: &str = "TELEOP_IPC_ROOT";
/// Environment variable with the iceoryx2 prefix for shared-memory and lock files.
pub const ENV_IPC_PREFIX: &str = "TELEOP_IPC_PREFIX";
/// Environment variable with the process's topic namespace (e.g. `left`; unset or empty: none).
pub const ENV_NAMESPACE: &str = "TELEOP_NAMESPACE";

/// iceoryx2's root directory when the settings name none.
pub(crate) const DEFAULT_ROOT: &str = "/tmp/iceoryx2/";

/// Samples a subscriber can queue before the oldest is overwritten (and counted as dropped).
pub(crate) const SUBSCRIBER_BUFFER: usize = 256;
const MAX_PUBLISHERS: usize = 16;
const MAX_SUBSCRIBERS: usize = 16;
const MAX_NODES: usize = 32;

/// Errors of the runtime. Each names the operation and the service or node it concerns.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// The IPC settings are not usable.
    #[error("invalid iceoryx2 setting {what}: {value:?} ({reason})")]
    Settings {
        /// Which setting.
        what: &'static str,
        /// Its value.
        value: String,
        /// Why it was refused.
        reason: String,
    },
    /// An iceoryx2 call failed.
    #[error("{operation} {name:?} failed: {detail}")]
    Ipc {
        /// What was being done.
        operation: &'static str,
        /// The node or service name.
        name: String,
        /// iceoryx2's error.
        detail: String,
    },
    /// Another `teleop launch` runs a session on the same IPC root and prefix.
    #[error(
        "another session runs on IPC prefix {prefix:?} in {root} ({holder}): one session per \
         prefix (stop it, or give this one its own TELEOP_IPC_PREFIX)"
    )]
    SessionRunning {
        /// The iceoryx2 root directory.
        root: String,
        /// The prefix.
        prefix: String,
        /// Who holds it (`pid N`).
        holder: String,
    },
    /// A command topic (one writer per namespace) already has a live publisher.
    #[error(
        "{topic} already has {others} live writer(s): a command topic takes one writer (is \
         another session or tool running on this IPC prefix? `teleop topics` shows it)"
    )]
    SecondWriter {
        /// The topic, with its namespace.
        topic: String,
        /// Its other publishers.
        others: usize,
    },
    /// A topic's service exists with another payload type: a process built with another
    /// version of the message contract (`teleop_msgs::CONTRACT_VERSION`) created it.
    #[error(
        "contract version mismatch on service {service}: this process uses `{ours}`, the \
         service was created with `{theirs}`; build every pipeline process from the same \
         message contract"
    )]
    ContractMismatch {
        /// The iceoryx2 service name, e.g. `teleop/hand/state`.
        service: String,
        /// This process's payload type name and size.
        ours: String,
        /// The service's payload type name and size (`unknown` when it could not be read).
        theirs: String,
    },
}

impl RuntimeError {
    pub(crate) fn ipc(operation: &'static str, name: &str, detail: impl core::fmt::Debug) -> Self {
        Self::Ipc {
            operation,
            name: name.to_string(),
            detail: format!("{detail:?}"),
        }
    }
}

/// Where the pipeline's iceoryx2 resources live, and the namespace a process's topics live in.
/// Processes see each other only with equal root and prefix; `teleop launch` passes its own to
/// every child through [`ENV_IPC_ROOT`] and [`ENV_IPC_PREFIX`], and each process's namespace
/// (the launch file's `namespace` key) through [`ENV_NAMESPACE`].
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct IpcSettings {
    /// Root directory for iceoryx2's files (default: iceoryx2's `/tmp/iceoryx2/`).
    pub root: Option<String>,
    /// Prefix of shared-memory and lock files (default: `teleop_`).
    pub prefix: Option<String>,
    /// Namespace of the node's topics (`left` makes `glove/state` the service
    /// `teleop/left/glove/state`); `None`: the plain topic names. Checked by
    /// [`namespace`](Self::namespace) when a [`NodeRuntime`] is made.
    pub namespace: Option<String>,
}

impl IpcSettings {
    /// Settings from [`ENV_IPC_ROOT`], [`ENV_IPC_PREFIX`] and [`ENV_NAMESPACE`] (unset or
    /// empty = default).
    pub fn from_env() -> Self {
        let get = |k| std::env::var(k).ok().filter(|v: &String| !v.is_empty());
        Self {
            root: get(ENV_IPC_ROOT),
            prefix: get(ENV_IPC_PREFIX),
            namespace: get(ENV_NAMESPACE),
        }
    }

    /// The checked namespace (`None`: the plain topic names).
    pub fn namespace(&self) -> Result<Option<Namespace>, RuntimeError> {
        self.namespace
            .as_deref()
            .map(|n| {
                Namespace::new(n).map_err(|e| RuntimeError::Settings {
                    what: "namespace",
                    value: n.to_string(),
                    reason: e.to_string(),
                })
            })
            .transpose()
    }

    /// Settings no other process or test uses: root `root_dir`, a prefix unique to this process
    /// and call. For tests and for throw-away sessions.
    pub fn isolated(root_dir: &std::path::Path) -> Self {
        use std::sync::atomic::{AtomicU32, Ordering};
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        Self {
            root: Some(root_dir.to_string_lossy().into_owned()),
            prefix: Some(format!("t{}x{n}_", std::process::id())),
            namespace: None,
        }
    }

    /// Removes the files iceoryx2 leaves in `/dev/shm` for this prefix (its per-prefix
    /// management segment outlives every node). Only for [`isolated`](Self::isolated) settings,
    /// once nothing uses them any more.
    pub fn remove_shared_memory(&self) {
        let Some(prefix) = &self.prefix else {
            return;
        };
        if let Ok(entries) = std::fs::read_dir("/dev/shm") {
            for entry in entries.flatten() {
                if entry
                    .file_name()
                    .to_string_lossy()
                    .starts_with(prefix.as_str())
                {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
    }

    /// The directory of iceoryx2's files (and of the e-stop latches and the session lock).
    pub fn root_dir(&self) -> std::path::PathBuf {
        std::path::PathBuf::from(self.root.as_deref().unwrap_or(DEFAULT_ROOT))
    }

    /// The prefix of the pipeline's files.
    pub fn file_prefix(&self) -> &str {
        self.prefix.as_deref().unwrap_or("teleop_")
    }

    /// Takes the one session of these settings' root and prefix (`teleop launch` does, for the
    /// whole session): a second is refused naming the holder's pid. The lock is an exclusive
    /// `flock` on `<root>/<prefix>session.lock`, released by the kernel when the holder exits,
    /// however it exits.
    pub fn lock_session(&self) -> Result<SessionLock, RuntimeError> {
        use std::io::{Read, Seek, Write};
        use std::os::fd::AsRawFd;
        use std::os::unix::fs::OpenOptionsExt;
        self.config()?;
        let path = self
            .root_dir()
            .join(format!("{}session.lock", self.file_prefix()));
        let failed = |reason: String| RuntimeError::Settings {
            what: "session lock",
            value: path.display().to_string(),
            reason,
        };
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .custom_flags(libc::O_NOFOLLOW)
            .mode(0o644)
            .open(&path)
            .map_err(|e| failed(e.to_string()))?;
        // SAFETY: flock(2) on a descriptor this function owns.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let error = std::io::Error::last_os_error();
            if error.raw_os_error() != Some(libc::EWOULDBLOCK) {
                return Err(failed(error.to_string()));
            }
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            return Err(RuntimeError::SessionRunning {
                root: self.root_dir().display().to_string(),
                prefix: self.file_prefix().to_string(),
                holder: holder.trim().to_string(),
            });
        }
        let written = file
            .set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| write!(file, "pid {}", std::process::id()));
        if let Err(e) = written {
            // The lock holds without the text; only the message of a refused second session
            // loses the pid.
            tracing::warn!(path = %path.display(), "session lock taken, pid not written: {e}");
        }
        Ok(SessionLock { _file: file })
    }

    /// The environment variables that carry these settings to a child process.
    pub fn to_env(&self) -> Vec<(&'static str, String)> {
        let mut env = Vec::new();
        if let Some(root) = &self.root {
            env.push((ENV_IPC_ROOT, root.clone()));
        }
        if let Some(prefix) = &self.prefix {
            env.push((ENV_IPC_PREFIX, prefix.clone()));
        }
        if let Some(namespace) = &self.namespace {
            env.push((ENV_NAMESPACE, namespace.clone()));
        }
        env
    }

    /// The iceoryx2 configuration for these settings.
    pub fn config(&self) -> Result<Config, RuntimeError> {
        let mut config = Config::default();
        let prefix = self.prefix.as_deref().unwrap_or("teleop_");
        config.global.prefix =
            FileName::new(prefix.as_bytes()).map_err(|e| RuntimeError::Settings {
                what: "prefix",
                value: prefix.to_string(),
                reason: format!("{e:?}; use letters, digits, '_' or '-'"),
            })?;
        // The root is made if missing (iceoryx2 would make its default one on first use, and
        // the session lock and the e-stop latches live in it before that) and checked: the
        // default root is shared by every user of the machine, a configured one may be too.
        let mut root = self.root.as_deref().unwrap_or(DEFAULT_ROOT).to_string();
        if !root.ends_with('/') {
            root.push('/');
        }
        std::fs::create_dir_all(&root).map_err(|e| RuntimeError::Settings {
            what: "root path",
            value: root.clone(),
            reason: e.to_string(),
        })?;
        check_root(std::path::Path::new(&root))?;
        if self.root.is_some() {
            let path = Path::new(root.as_bytes()).map_err(|e| RuntimeError::Settings {
                what: "root path",
                value: root.clone(),
                reason: format!("{e:?}"),
            })?;
            config.global.set_root_path(&path);
        }
        Ok(config)
    }
}

/// The one session of an IPC root and prefix ([`IpcSettings::lock_session`]), held until
/// dropped (or the process ends).
#[derive(Debug)]
pub struct SessionLock {
    _file: std::fs::File,
}

/// Refuses an IPC root that another user owns or that others may write to: its e-stop latches
/// and iceoryx2's files would be theirs to remove, replace or point elsewhere.
fn check_root(root: &std::path::Path) -> Result<(), RuntimeError> {
    use std::os::unix::fs::MetadataExt;
    let refused = |reason: String| RuntimeError::Settings {
        what: "root path",
        value: root.display().to_string(),
        reason,
    };
    let meta = std::fs::metadata(root).map_err(|e| refused(e.to_string()))?;
    // SAFETY: geteuid(2) cannot fail.
    let me = unsafe { libc::geteuid() };
    if meta.uid() != me {
        return Err(refused(format!(
            "owned by uid {}, not by this user (uid {me}); use a directory of your own",
            meta.uid()
        )));
    }
    if meta.mode() & 0o002 != 0 {
        return Err(refused(format!(
            "writable by every user (mode {:o}); `chmod o-w` it",
            meta.mode() & 0o7777
        )));
    }
    Ok(())
}

/// A pipeline process's iceoryx2 node and the factory for its ports.
pub struct NodeRuntime {
    node: Node<Service>,
    name: String,
    namespace: Option<Namespace>,
    source_id: u32,
    estop_latch: std::path::PathBuf,
    plain_estop_latch: std::path::PathBuf,
}

impl NodeRuntime {
    /// Creates the iceoryx2 node `name` (visible in `teleop nodes`). In a namespace the node is
    /// called `<namespace>/<name>` and its ports use the namespace's topics.
    pub fn new(name: &str, settings: &IpcSettings) -> Result<Self, RuntimeError> {
        crate::signals::take_over_stop_signals();
        crate::signals::follow_supervisor();
        crate::realtime::setup_process();
        let namespace = settings.namespace()?;
        let config = settings.config()?;
        let name = qualified(namespace.as_ref(), name);
        let node_name = NodeName::new(&name).map_err(|e| RuntimeError::Settings {
            what: "node name",
            value: name.clone(),
            reason: format!("{e:?}"),
        })?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&config)
            .create::<Service>()
            .map_err(|e| RuntimeError::ipc("creating node", &name, e))?;
        Ok(Self {
            node,
            source_id: teleop_msgs::source_id(&name),
            estop_latch: crate::estop::latch_path(settings, namespace.as_ref()),
            plain_estop_latch: crate::estop::latch_path(settings, None),
            name,
            namespace,
        })
    }

    /// The node's name (with its namespace).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The namespace of the node's topics.
    pub fn namespace(&self) -> Option<&Namespace> {
        self.namespace.as_ref()
    }

    /// The e-stop latch file of the node's namespace (see [`EStopInput`](crate::EStopInput)).
    pub fn estop_latch(&self) -> &std::path::Path {
        &self.estop_latch
    }

    /// The latch file of the topics without a namespace: it stops every namespace too.
    pub fn plain_estop_latch(&self) -> &std::path::Path {
        &self.plain_estop_latch
    }

    /// The id this node writes into the headers it stamps.
    pub fn source_id(&self) -> u32 {
        self.source_id
    }

    /// The underlying iceoryx2 node.
    pub fn node(&self) -> &Node<Service> {
        &self.node
    }

    /// A publisher for `M`'s topic in the node's namespace (creates the service if needed).
    pub fn publisher<M: Message>(&self) -> Result<Publisher<M>, RuntimeError> {
        self.publisher_in(self.namespace.as_ref())
    }

    /// A publisher for `M`'s topic in `namespace` (for tools that serve several namespaces).
    /// On a command topic ([`SINGLE_WRITER_TOPICS`](teleop_msgs::SINGLE_WRITER_TOPICS)) a
    /// publisher beside another live one is refused ([`RuntimeError::SecondWriter`]).
    pub fn publisher_in<M: Message>(
        &self,
        namespace: Option<&Namespace>,
    ) -> Result<Publisher<M>, RuntimeError> {
        self.make_publisher(namespace, false)
    }

    /// [`publisher_in`](Self::publisher_in) that accepts other writers on a command topic
    /// (`teleop replay --allow-live`): the caller names the topic loudly; the number of writers
    /// it found is logged as a warning here.
    pub fn publisher_beside_live_in<M: Message>(
        &self,
        namespace: Option<&Namespace>,
    ) -> Result<Publisher<M>, RuntimeError> {
        self.make_publisher(namespace, true)
    }

    fn make_publisher<M: Message>(
        &self,
        namespace: Option<&Namespace>,
        beside_live: bool,
    ) -> Result<Publisher<M>, RuntimeError> {
        use iceoryx2::prelude::PortFactory;
        let (service, topic) = service_name::<M>(namespace)?;
        let pubsub = self.pubsub::<M>(&service, &topic)?;
        let publisher = pubsub
            .publisher_builder()
            .create()
            .map_err(|e| RuntimeError::ipc("creating publisher", &topic, e))?;
        if teleop_msgs::SINGLE_WRITER_TOPICS.contains(&M::TOPIC) {
            let mut writers = pubsub.dynamic_config().number_of_publishers();
            if writers > 1 {
                // A writer that died without closing its port still counts until its node's
                // resources are cleaned up.
                clean_dead_nodes(self.node.config());
                writers = pubsub.dynamic_config().number_of_publishers();
            }
            if writers > 1 && !beside_live {
                return Err(RuntimeError::SecondWriter {
                    topic,
                    others: writers - 1,
                });
            }
            if writers > 1 {
                tracing::warn!(
                    topic = %topic,
                    others = writers - 1,
                    "publishing beside another live writer of a command topic"
                );
            }
        }
        let notifier = self
            .event(&service, &topic)?
            .notifier_builder()
            .create()
            .map_err(|e| RuntimeError::ipc("creating notifier", &topic, e))?;
        Ok(Publisher::new(publisher, notifier, self.source_id))
    }

    /// A subscriber for `M`'s topic in the node's namespace (creates the service if needed). It
    /// receives the newest sample published before it existed, if any.
    pub fn subscriber<M: Message>(&self) -> Result<Subscriber<M>, RuntimeError> {
        self.subscriber_in(self.namespace.as_ref())
    }

    /// A subscriber for `M`'s topic in `namespace` (for tools that serve several namespaces).
    pub fn subscriber_in<M: Message>(
        &self,
        namespace: Option<&Namespace>,
    ) -> Result<Subscriber<M>, RuntimeError> {
        let (service, topic) = service_name::<M>(namespace)?;
        let pubsub = self.pubsub::<M>(&service, &topic)?;
        let subscriber = pubsub
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| RuntimeError::ipc("creating subscriber", &topic, e))?;
        let listener = self
            .event(&service, &topic)?
            .listener_builder()
            .create()
            .map_err(|e| RuntimeError::ipc("creating listener", &topic, e))?;
        Ok(Subscriber::new(subscriber, listener))
    }

    /// Publishers and subscribers of `M`'s topic in the node's namespace, `None` when the topic
    /// does not exist (yet). Does not create anything.
    pub fn topic_ports<M: Message>(&self) -> Option<(usize, usize)> {
        self.topic_ports_in::<M>(self.namespace.as_ref())
    }

    /// `M`'s publish-subscribe service in `namespace`, if it exists (nothing is created).
    fn existing_pubsub<M: Message>(
        &self,
        namespace: Option<&Namespace>,
    ) -> Option<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Service, M, ()>>
    {
        let (service, _) = service_name::<M>(namespace).ok()?;
        self.node
            .service_builder(&service)
            .publish_subscribe::<M>()
            .open()
            .ok()
    }

    /// Publishers and subscribers of `M`'s topic in `namespace`, `None` when the topic does not
    /// exist (yet). Does not create anything.
    pub fn topic_ports_in<M: Message>(
        &self,
        namespace: Option<&Namespace>,
    ) -> Option<(usize, usize)> {
        use iceoryx2::prelude::PortFactory;
        let pubsub = self.existing_pubsub::<M>(namespace)?;
        let dynamic = pubsub.dynamic_config();
        Some((
            dynamic.number_of_publishers(),
            dynamic.number_of_subscribers(),
        ))
    }

    /// The names of the live nodes that have a publisher of `M`'s topic in `namespace`, sorted,
    /// one entry per node (two nodes of one name give the name twice); `None` when the topic
    /// does not exist (yet). A dead node's publishers are left out (its process is gone); a node
    /// whose state or name cannot be read is listed by its iceoryx2 id. Creates nothing.
    pub fn topic_publisher_nodes_in<M: Message>(
        &self,
        namespace: Option<&Namespace>,
    ) -> Option<Vec<String>> {
        use iceoryx2::node::{NodeState, NodeView};
        use iceoryx2::prelude::{CallbackProgression, PortFactory};
        let pubsub = self.existing_pubsub::<M>(namespace)?;
        let mut ids = Vec::new();
        pubsub.dynamic_config().list_publishers(|p| {
            if !ids.contains(&p.node_id) {
                ids.push(p.node_id);
            }
            CallbackProgression::Continue
        });
        let mut names = Vec::new();
        let listed = Node::<Service>::list(self.node.config(), |state| {
            let (id, name) = match &state {
                NodeState::Alive(view) => (
                    *view.id(),
                    view.details()
                        .as_ref()
                        .map(|d| d.name().as_str().to_string()),
                ),
                NodeState::Dead(_) => return CallbackProgression::Continue,
                NodeState::Inaccessible(id) | NodeState::Undefined(id) => (*id, None),
            };
            if ids.contains(&id) {
                names.push(name.unwrap_or_else(|| format!("iceoryx2 node {id}")));
            }
            CallbackProgression::Continue
        });
        if listed.is_err() {
            // The nodes cannot be listed: every publisher counts, unnamed.
            names = ids.iter().map(|id| format!("iceoryx2 node {id}")).collect();
        }
        names.sort();
        Some(names)
    }

    fn pubsub<M: Message>(
        &self,
        service: &ServiceName,
        topic: &str,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<Service, M, ()>,
        RuntimeError,
    > {
        use iceoryx2::service::builder::publish_subscribe::PublishSubscribeCreateError as Create;
        use PublishSubscribeOpenOrCreateError as E;
        retry_interrupted(
            || {
                self.node
                    .service_builder(service)
                    .publish_subscribe::<M>()
                    .history_size(1)
                    .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
                    .enable_safe_overflow(true)
                    .max_publishers(MAX_PUBLISHERS)
                    .max_subscribers(MAX_SUBSCRIBERS)
                    .max_nodes(MAX_NODES)
                    .open_or_create()
            },
            |e| {
                matches!(
                    e,
                    E::PublishSubscribeOpenError(PublishSubscribeOpenError::Interrupt)
                        | E::PublishSubscribeCreateError(Create::Interrupt)
                )
            },
        )
        .map_err(|e| pubsub_error::<M>(&self.node, service, topic, e))
    }

    fn event(
        &self,
        service: &ServiceName,
        topic: &str,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Service>, RuntimeError> {
        use iceoryx2::service::builder::event::{
            EventCreateError, EventOpenError, EventOpenOrCreateError as E,
        };
        retry_interrupted(
            || {
                self.node
                    .service_builder(service)
                    .event()
                    .max_notifiers(MAX_PUBLISHERS)
                    .max_listeners(MAX_SUBSCRIBERS)
                    .max_nodes(MAX_NODES)
                    .open_or_create()
            },
            |e| {
                matches!(
                    e,
                    E::EventOpenError(EventOpenError::Interrupt)
                        | E::EventCreateError(EventCreateError::Interrupt)
                )
            },
        )
        .map_err(|e| RuntimeError::ipc("opening event service", topic, e))
    }
}

/// Tries `open` again when a signal interrupted it (`interrupted`): a SIGINT while a node creates
/// its ports is recorded and stops the node's loop at its first wake, so the node finishes
/// starting and then stops cleanly (a recorder closes its file) instead of failing. At most 100
/// tries.
fn retry_interrupted<T, E>(
    mut open: impl FnMut() -> Result<T, E>,
    interrupted: impl Fn(&E) -> bool,
) -> Result<T, E> {
    let mut tries = 0;
    loop {
        match open() {
            Err(e) if interrupted(&e) && tries < 100 => tries += 1,
            other => return other,
        }
    }
}

/// The iceoryx2 service name of a topic, `teleop/<topic>` or `teleop/<namespace>/<topic>`, and
/// the qualified topic name (for messages).
fn service_name<M: Message>(
    namespace: Option<&Namespace>,
) -> Result<(ServiceName, String), RuntimeError> {
    let topic = qualified(namespace, M::TOPIC);
    let name = service_name_of(&topic);
    let service = ServiceName::new(&name).map_err(|e| RuntimeError::Settings {
        what: "service name",
        value: name.clone(),
        reason: format!("{e:?}"),
    })?;
    Ok((service, topic))
}

fn service_name_of(qualified_topic: &str) -> String {
    format!("{SERVICE_PREFIX}{qualified_topic}")
}

/// The namespaces among iceoryx2 service names: those of every service named
/// `teleop/<namespace>/<topic>` of a contract topic, sorted, each once.
fn namespaces_of<'a>(service_names: impl IntoIterator<Item = &'a str>) -> Vec<Namespace> {
    let mut found: Vec<Namespace> = service_names
        .into_iter()
        .filter_map(|s| teleop_namespace::split(s.strip_prefix(SERVICE_PREFIX)?)?.0)
        .collect();
    found.sort();
    found.dedup();
    found
}

/// The namespaces in use by the pipeline of `settings`: every namespace with at least one
/// service of a contract topic (a node in a namespace creates its services when it starts).
/// The plain topics (no namespace) are not listed.
pub fn discover_namespaces(settings: &IpcSettings) -> Result<Vec<Namespace>, RuntimeError> {
    use iceoryx2::prelude::CallbackProgression;
    use iceoryx2::service::Service as _;
    let config = settings.config()?;
    let mut names: Vec<String> = Vec::new();
    Service::list(&config, |details| {
        names.push(details.static_details.name().as_str().to_string());
        CallbackProgression::Continue
    })
    .map_err(|e| RuntimeError::ipc("listing services", "teleop/*", e))?;
    Ok(namespaces_of(names.iter().map(String::as_str)))
}

/// Why `M`'s publish-subscribe service could not be opened: a contract version mismatch when it
/// exists with another payload type (iceoryx2 compares type names, which carry the contract
/// version, and sizes), else iceoryx2's error.
fn pubsub_error<M: Message>(
    node: &Node<Service>,
    service: &ServiceName,
    topic: &str,
    error: PublishSubscribeOpenOrCreateError,
) -> RuntimeError {
    if !matches!(
        error,
        PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            PublishSubscribeOpenError::IncompatibleTypes
        )
    ) {
        return RuntimeError::ipc("opening publish-subscribe service", topic, error);
    }
    let theirs = <Service as iceoryx2::service::Service>::details(
        service,
        node.config(),
        iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
    )
    .ok()
    .flatten()
    .and_then(|details| match details.static_details.messaging_pattern() {
        StaticPattern::PublishSubscribe(config) => {
            let payload = config.message_type_details().payload;
            Some(format!(
                "{} ({} bytes)",
                payload.type_name(),
                payload.size()
            ))
        }
        _ => None,
    });
    RuntimeError::ContractMismatch {
        service: service.as_str().to_string(),
        ours: format!("{} ({} bytes)", M::TYPE_NAME, core::mem::size_of::<M>()),
        theirs: theirs.unwrap_or_else(|| "unknown".to_string()),
    }
}

/// Removes the iceoryx2 resources of nodes whose process died (e.g. killed with SIGKILL), so
/// their ports no longer count (a command topic's one writer) and their restarted successors
/// start clean. Logs what it removed.
pub fn clean_dead_nodes(config: &Config) {
    use iceoryx2::node::{NodeState, NodeView};
    use iceoryx2::prelude::CallbackProgression;
    let mut dead = Vec::new();
    let _ = Node::<Service>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    for view in dead {
        let name = view
            .details()
            .as_ref()
            .map(|d| d.name().as_str().to_string())
            .unwrap_or_default();
        match view.try_remove_stale_resources() {
            Ok(_) => {
                tracing::info!(node = %name, "cleaned up the resources of a dead iceoryx2 node")
            }
            Err(e) => tracing::warn!(node = %name, "cannot clean up dead iceoryx2 node: {e:?}"),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn interrupted_opens_are_tried_again_up_to_a_bound() {
        let mut calls = 0;
        let r: Result<u8, &str> = retry_interrupted(
            || {
                calls += 1;
                if calls < 3 {
                    Err("interrupted")
                } else {
                    Ok(7)
                }
            },
            |e| *e == "interrupted",
        );
        assert_eq!((r, calls), (Ok(7), 3));
        let mut calls = 0;
        let r: Result<u8, &str> = retry_interrupted(
            || {
                calls += 1;
                Err("interrupted")
            },
            |e| *e == "interrupted",
        );
        assert_eq!((r, calls), (Err("interrupted"), 101));
        let r: Result<u8, &str> = retry_interrupted(|| Err("refused"), |e| *e == "interrupted");
        assert_eq!(r, Err("refused"), "other errors at once");
    }
    use teleop_msgs::{GloveState, HandCommand, NodeHealth};

    #[test]
    fn a_second_writer_of_a_command_topic_is_refused_and_a_dead_ones_port_does_not_count() {
        let dir = tempfile::tempdir().unwrap();
        let settings = IpcSettings::isolated(dir.path());
        let a = NodeRuntime::new("a", &settings).unwrap();
        let b = NodeRuntime::new("b", &settings).unwrap();
        let first = a.publisher::<HandCommand>().unwrap();
        let e = b
            .publisher::<HandCommand>()
            .err()
            .expect("second writer refused");
        assert!(
            matches!(&e, RuntimeError::SecondWriter { topic, others: 1 } if topic == "hand/command"),
            "{e}"
        );
        assert!(
            e.to_string().contains("a command topic takes one writer"),
            "{e}"
        );
        // Sensor topics take several writers; the named exception takes a command topic.
        let _s1 = a.publisher::<GloveState>().unwrap();
        let _s2 = b.publisher::<GloveState>().unwrap();
        let beside = b.publisher_beside_live_in::<HandCommand>(None).unwrap();
        drop(beside);
        // Once the first writer is gone, the topic is free again.
        drop(first);
        let _second = b.publisher::<HandCommand>().unwrap();
        drop((a, b));
        settings.remove_shared_memory();
    }

    #[test]
    fn one_session_per_prefix_the_second_names_the_holder() {
        let dir = tempfile::tempdir().unwrap();
        let settings = IpcSettings::isolated(dir.path());
        let held = settings.lock_session().unwrap();
        let e = settings.lock_session().unwrap_err().to_string();
        assert!(
            e.contains(&format!("(pid {})", std::process::id()))
                && e.contains("one session per prefix"),
            "{e}"
        );
        let other = IpcSettings::isolated(dir.path());
        let _other = other
            .lock_session()
            .expect("another prefix is another session");
        drop(held);
        let _again = settings
            .lock_session()
            .expect("free once the holder is gone");
    }

    #[test]
    fn a_session_on_a_root_not_made_yet_makes_it() {
        // As on a machine just booted, where iceoryx2's default /tmp/iceoryx2 is not there
        // until something makes it (the default root takes this same path).
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("not/there/yet");
        let settings = IpcSettings::isolated(&root);
        let _held = settings.lock_session().expect("the root is made");
        assert!(root.is_dir());
    }

    #[test]
    fn an_ipc_root_others_may_write_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("root");
        std::fs::create_dir(&root).unwrap();
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o777)).unwrap();
        let settings = IpcSettings::isolated(&root);
        let e = settings.config().unwrap_err().to_string();
        assert!(e.contains("writable by every user (mode 777)"), "{e}");
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o755)).unwrap();
        settings.config().unwrap();
        if unsafe { libc::geteuid() } == 0 {
            // Owned by another user (root can hand it over).
            std::os::unix::fs::chown(&root, Some(65534), None).unwrap();
            let e = settings.config().unwrap_err().to_string();
            assert!(e.contains("owned by uid 65534, not by this user"), "{e}");
        }
    }

    #[test]
    fn service_names_without_a_namespace_are_unchanged() {
        let (service, topic) = service_name::<GloveState>(None).unwrap();
        assert_eq!(
            (service.as_str(), topic.as_str()),
            ("teleop/glove/state", "glove/state")
        );
        let (service, _) = service_name::<NodeHealth>(None).unwrap();
        assert_eq!(service.as_str(), "teleop/health");
    }

    #[test]
    fn service_names_in_a_namespace() {
        let left = Namespace::new("left").unwrap();
        let (service, topic) = service_name::<GloveState>(Some(&left)).unwrap();
        assert_eq!(
            (service.as_str(), topic.as_str()),
            ("teleop/left/glove/state", "left/glove/state")
        );
        let (service, _) = service_name::<NodeHealth>(Some(&left)).unwrap();
        assert_eq!(service.as_str(), "teleop/left/health");
    }

    #[test]
    fn namespaces_from_service_names() {
        let found = namespaces_of([
            "teleop/glove/state",
            "teleop/right/hand/command",
            "teleop/left/health",
            "teleop/left/glove/state",
            "teleop/cell2/left/estop",
            "teleop/left/not_a_topic",
            "other/up/glove/state",
            "teleop/Bad/glove/state",
        ]);
        let names: Vec<&str> = found.iter().map(Namespace::as_str).collect();
        assert_eq!(names, ["cell2/left", "left", "right"]);
    }

    #[test]
    fn invalid_namespace_setting_is_an_error() {
        let settings = IpcSettings {
            namespace: Some("Left/".into()),
            ..IpcSettings::default()
        };
        let e = settings.namespace().unwrap_err().to_string();
        assert!(e.contains("namespace") && e.contains("\"Left/\""), "{e}");
        let settings = IpcSettings {
            namespace: Some("left".into()),
            ..IpcSettings::default()
        };
        assert_eq!(settings.namespace().unwrap().unwrap().as_str(), "left");
    }
}
