//! Where a peer's Deliver service listens (`rosrpc://host:port`): the ROS master of this node,
//! or in tests a table.

/// Why a service was not located.
#[derive(Debug, thiserror::Error)]
pub enum LocatorError {
    /// No client for this node's master at `uri` (`ROS_MASTER_URI`, `__master:=`). rosrust's
    /// error is not `Sync`, so its text is kept.
    #[error("the ROS master at {uri}: {reason}")]
    Master { uri: String, reason: String },
    /// The master did not say where `service` listens (not registered, or no answer).
    #[error("lookup of {service} at the master: {source}")]
    Lookup { service: String, source: rosrust::error::ResponseError },
}

/// For tools that report errors as text: `?` in a function returning `Result<_, String>`
/// (`sgm_rogue`).
impl From<LocatorError> for String {
    fn from(e: LocatorError) -> Self {
        e.to_string()
    }
}

/// Finds where a service listens (`rosrpc://host:port`); the ROS master in the node.
pub trait Locator: Send + Sync + 'static {
    fn lookup(&self, service: &str) -> Result<String, LocatorError>;
}

/// The node's ROS master.
pub struct MasterLocator {
    master: rosrust::api::Master,
}

impl MasterLocator {
    /// The master of the running rosrust node (after `rosrust::try_init`).
    pub fn of_this_node() -> Result<Self, LocatorError> {
        let uri = rosrust::api::resolve::master();
        let master = rosrust::api::Master::new(&uri, &rosrust::name(), &rosrust::uri())
            .map_err(|e| LocatorError::Master { uri, reason: e.to_string() })?;
        Ok(Self { master })
    }
}

impl Locator for MasterLocator {
    fn lookup(&self, service: &str) -> Result<String, LocatorError> {
        self.master.lookup_service(service).map_err(|source| LocatorError::Lookup { service: service.into(), source })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::call::CallError;

    #[test]
    fn errors_name_the_service_or_the_master() {
        let source = rosrust::error::ResponseError::Server("no provider".into());
        let lookup = LocatorError::Lookup { service: "/sgm/robot_2/deliver".into(), source };
        let call = CallError::from(lookup);
        assert_eq!(call.to_string(), "lookup of /sgm/robot_2/deliver at the master: Server error: no provider");
        let master = LocatorError::Master { uri: "http://nowhere:11311/".into(), reason: "refused".into() };
        assert_eq!(String::from(master), "the ROS master at http://nowhere:11311/: refused");
    }
}
