//! A fleet on many machines, on the orchestrators fleets already run: the
//! same services as the Compose file ([`Fleet::services`]), written as a
//! Docker Swarm stack or as Kubernetes manifests.
//!
//! On many machines each host of the cfg gets a Zenoh router of its own,
//! placed on the host's machines beside it; the host's nodes are its
//! clients, so what they say to each other stays on that machine, and the
//! hosts' routers link to the fleet's router: a device on another machine
//! is a router hop or two away. Hosts are placed by node labels, a label
//! per host (`troupe.host.sim=true` in a swarm, `troupe.host/sim=true` in a
//! cluster), so that one machine can carry several hosts (a one-node swarm
//! carries them all).

use std::fmt::Write as _;

use crate::docker::{yaml_list, yaml_str, Fleet, Layout, Service, Source};

/// The label a swarm node carries to run `host`'s services.
pub fn swarm_label(host: &str) -> String {
    format!("troupe.host.{host}")
}

/// The label a Kubernetes node carries to run `host`'s services.
pub fn k8s_label(host: &str) -> String {
    format!("troupe.host/{host}")
}

/// Names a swarm's or a cluster's services may take: a host's router is
/// `router-HOST`, a DNS label of at most 63 characters.
fn check_names(services: &[Service]) -> anyhow::Result<()> {
    for s in services {
        if s.name.len() > 63 {
            anyhow::bail!(
                "service `{}` has more than 63 characters: a host's name must have at most 56",
                s.name
            );
        }
    }
    Ok(())
}

/// The services on many machines, and the file's first line.
fn opening(fleet: &Fleet<'_>) -> anyhow::Result<(Vec<Service>, String)> {
    let services = fleet.services(Layout::RouterPerHost)?;
    check_names(&services)?;
    let first = format!(
        "# Written by `{}`; regenerate rather than edit.\n",
        fleet.command
    );
    Ok((services, first))
}

/// The hosts the services are placed on, in order.
fn placed(services: &[Service]) -> Vec<&str> {
    let mut hosts: Vec<&str> = services.iter().filter_map(|v| v.place.as_deref()).collect();
    hosts.dedup();
    hosts
}

fn path<'f>(fleet: &'f Fleet<'_>) -> &'f str {
    match &fleet.source {
        Source::InImage(p) => p,
        Source::Mounted { file, .. } => file,
    }
}

/// The fleet as a Docker Swarm stack file.
///
/// # Errors
///
/// A plan whose hosts cannot be services.
pub fn swarm(fleet: &Fleet<'_>) -> anyhow::Result<String> {
    let (services, mut s) = opening(fleet)?;
    let hosts = placed(&services);
    let labels: Vec<String> = hosts
        .iter()
        .map(|h| format!("--label-add {}=true", swarm_label(h)))
        .collect();
    let _ = write!(
        s,
        "#\n\
         # A Docker Swarm stack ({} in the image). On every node (there is no registry:\n\
         # each node has its own copy of the image):\n\
         #   target/release/troupe image\n\
         # Place each host of the cfg: a node runs the hosts whose label it carries\n\
         # (one node may carry several; a one-node swarm carries them all):\n\
         #   docker node update {} NODE\n\
         # Then, on a manager:\n\
         #   docker stack deploy -c FILE fleet     # up\n\
         #   docker stack rm fleet                 # down\n\
         #\n\
         # Each host runs beside a router of its own (router-HOST, on the same\n\
         # node), its nodes that router's clients; the hosts' routers link to the\n\
         # fleet's router. --reconnect: a container keeps trying its router, so\n\
         # start order does not matter; --lease: a host cut off for that many\n\
         # seconds has its devices withdrawn. The router's and the bridge's ports\n\
         # are published on the node that runs each (set TROUPE_ROUTER_PORT and\n\
         # TROUPE_PORT_<robot> to move them); Player has no authentication:\n\
         # publish them on a trusted network only.\n\n",
        path(fleet),
        labels.join(" ")
    );
    s.push_str("version: \"3.8\"\n\nservices:\n");
    for svc in &services {
        svc.write_head(&mut s, &fleet.image);
        if !svc.ports.is_empty() {
            s.push_str("    ports:\n");
            for (var, p) in &svc.ports {
                // On the node that runs it: on these machines the routing
                // mesh refused connections to its published ports.
                let _ = writeln!(
                    s,
                    "      - target: {p}\n        published: ${{{var}-{p}}}\n        protocol: tcp\n        mode: host"
                );
            }
        }
        if let (Some(_), Some(who)) = (&fleet.keys, &svc.identity) {
            // Where the configs name each other (`--zenoh-config /keys/…`).
            s.push_str("    secrets:\n");
            for n in secret_list(who) {
                let _ = writeln!(s, "      - source: {n}\n        target: /keys/{n}");
            }
        }
        s.push_str("    networks: [fleet]\n");
        svc.write_health(&mut s);
        s.push_str("    deploy:\n      replicas: 1\n");
        s.push_str("      restart_policy:\n        condition: any\n        delay: 1s\n");
        if let Some(h) = &svc.place {
            let _ = writeln!(
                s,
                "      placement:\n        constraints: [{}]",
                yaml_str(&format!("node.labels.{} == true", swarm_label(h)))
            );
        }
        s.push('\n');
    }
    s.push_str("networks:\n  fleet:\n    driver: overlay\n    attachable: true\n");
    if let Some(dir) = &fleet.keys {
        s.push_str("\nsecrets:\n");
        let mut names: Vec<String> = services
            .iter()
            .filter_map(|v| v.identity.as_deref())
            .flat_map(secret_list)
            .collect();
        names.sort();
        names.dedup();
        for n in names {
            let _ = writeln!(
                s,
                "  {n}:\n    file: {}",
                yaml_str(&format!("{}/{n}", dir.trim_end_matches('/')))
            );
        }
    }
    Ok(s)
}

/// The secrets identity `who` reads: its config (and the router's
/// passwords), at /run/secrets.
fn secret_list(who: &str) -> Vec<String> {
    let mut v = vec![format!("{who}.json5")];
    if who == "router" {
        v.push(crate::keys::PASSWORDS.to_owned());
    }
    v
}

/// The fleet as Kubernetes manifests: one YAML stream.
///
/// # Errors
///
/// A plan whose hosts cannot be services.
pub fn k8s(fleet: &Fleet<'_>) -> anyhow::Result<String> {
    let (services, mut s) = opening(fleet)?;
    let hosts = placed(&services);
    let _ = write!(
        s,
        "#\n\
         # Kubernetes manifests ({} in the image, which every node holds: there is no\n\
         # registry). Place each host of the cfg: a node runs the hosts whose label it\n\
         # carries (one node may carry several):\n\
         #   kubectl label node NODE {}\n",
        path(fleet),
        hosts
            .iter()
            .map(|h| format!("{}=true", k8s_label(h)))
            .collect::<Vec<_>>()
            .join(" ")
    );
    if fleet.keys.is_some() {
        s.push_str(
            "# The fleet's keys (`troupe fleet-keys DIR`), as the Secret they mount from:\n\
             #   kubectl create secret generic troupe-keys --from-file=DIR\n",
        );
    }
    s.push_str(
        "#   kubectl apply -f FILE      # up\n\
         #   kubectl delete -f FILE     # down\n\
         # Player clients reach the bridge's Service (`kubectl port-forward\n\
         # service/bridge 6665`, or make it a NodePort or LoadBalancer).\n",
    );
    for svc in &services {
        s.push_str("---\n");
        deployment(&mut s, fleet, svc);
        let ports: Vec<(String, u16)> = match svc.listens {
            Some(p) => vec![("zenoh".to_owned(), p)],
            None => svc
                .ports
                .iter()
                .map(|(_, p)| (format!("player-{p}"), *p))
                .collect(),
        };
        if !ports.is_empty() {
            s.push_str("---\n");
            service(&mut s, svc, &ports);
        }
    }
    Ok(s)
}

fn labels(s: &mut String, indent: &str, svc: &Service) {
    let _ = writeln!(s, "{indent}app.kubernetes.io/part-of: troupe");
    let _ = writeln!(s, "{indent}troupe/service: {}", yaml_str(&svc.name));
}

/// A resource's kind and its metadata: `svc`'s name and labels.
fn head(s: &mut String, api: &str, kind: &str, svc: &Service) {
    let _ = writeln!(s, "apiVersion: {api}\nkind: {kind}\nmetadata:");
    let _ = writeln!(s, "  name: {}", svc.name);
    s.push_str("  labels:\n");
    labels(s, "    ", svc);
}

fn deployment(s: &mut String, fleet: &Fleet<'_>, svc: &Service) {
    let _ = writeln!(s, "# {}", svc.comment);
    head(s, "apps/v1", "Deployment", svc);
    s.push_str("spec:\n  replicas: 1\n  selector:\n    matchLabels:\n");
    let _ = writeln!(s, "      troupe/service: {}", yaml_str(&svc.name));
    s.push_str("  template:\n    metadata:\n      labels:\n");
    labels(s, "        ", svc);
    s.push_str("    spec:\n");
    if let Some(h) = &svc.place {
        let _ = writeln!(s, "      nodeSelector:\n        {}: \"true\"", k8s_label(h));
    }
    let _ = writeln!(
        s,
        "      securityContext:\n        runAsUser: {uid}\n        runAsGroup: {uid}\n        runAsNonRoot: true",
        uid = crate::docker::UID
    );
    s.push_str("      terminationGracePeriodSeconds: 10\n      containers:\n");
    let _ = writeln!(s, "        - name: {}", svc.name);
    let _ = writeln!(s, "          image: {}", yaml_str(&fleet.image));
    s.push_str("          imagePullPolicy: IfNotPresent\n");
    s.push_str("          command: [\"/troupe\"]\n");
    let _ = writeln!(s, "          args: {}", yaml_list(&svc.command));
    if let Some(p) = svc.listens {
        let _ = writeln!(
            s,
            "          ports:\n            - name: zenoh\n              containerPort: {p}"
        );
    } else if !svc.ports.is_empty() {
        s.push_str("          ports:\n");
        for (_, p) in &svc.ports {
            let _ = writeln!(
                s,
                "            - name: player-{p}\n              containerPort: {p}"
            );
        }
    }
    let _ = writeln!(
        s,
        "          readinessProbe:\n            exec:\n              command: {}\n            periodSeconds: 2\n            timeoutSeconds: 5\n            failureThreshold: 3",
        yaml_list(&svc.health_command())
    );
    if fleet.keys.is_some() && svc.identity.is_some() {
        s.push_str(
            "          volumeMounts:\n            - name: keys\n              mountPath: /keys\n              readOnly: true\n",
        );
        s.push_str(
            "      volumes:\n        - name: keys\n          secret:\n            secretName: troupe-keys\n",
        );
    }
}

fn service(s: &mut String, svc: &Service, ports: &[(String, u16)]) {
    head(s, "v1", "Service", svc);
    s.push_str("spec:\n  selector:\n");
    let _ = writeln!(s, "    troupe/service: {}", yaml_str(&svc.name));
    s.push_str("  ports:\n");
    for (name, p) in ports {
        let _ = writeln!(
            s,
            "    - name: {name}\n      port: {p}\n      targetPort: {p}\n      protocol: TCP"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_name_one_host_each_so_a_node_can_carry_several() {
        assert_eq!(swarm_label("robot1"), "troupe.host.robot1");
        assert_eq!(k8s_label("robot1"), "troupe.host/robot1");
    }
}
