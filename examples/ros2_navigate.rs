//! A `navigate_to_pose` action client of ours, on ros2-client, for the ROS 2 node's tests: it
//! frames the action's services as Fast DDS does (`enhanced`: the request's identity in the
//! RTPS message) or as Cyclone DDS does (`cyclone`: a 16-byte header in front of each request
//! and reply), sends one goal and prints each event as a JSON line: `accepted`, `feedback`,
//! `result`. Run it inside a network namespace of its own: DDS discovery multicasts.
//!
//! ```text
//! ros2_navigate --mapping enhanced|cyclone --x X --y Y [--seconds S] [--domain N]
//! ```
//!
//! Exit 0 once a result came, 3 when nothing answered in time, 2 on a usage error.

use std::process::ExitCode;
use std::time::Duration;

use chassisd::runtime::links::ros2::messages::{geometry_msgs, nav2_msgs, std_msgs};
use futures_util::StreamExt;
use ros2_client::action::ActionClientQosPolicies;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History};
use ros2_client::{
    ActionTypeName, Context, Name, NodeName, NodeOptions, QosProfile, ServiceMapping,
};
use serde_json::json;

/// What the command line asks for.
struct Args {
    mapping: ServiceMapping,
    x: f64,
    y: f64,
    seconds: f64,
    domain: u16,
}

fn parse(args: &[String]) -> Result<Args, String> {
    let mut parsed = Args {
        mapping: ServiceMapping::Enhanced,
        x: f64::NAN,
        y: f64::NAN,
        seconds: 30.0,
        domain: std::env::var("ROS_DOMAIN_ID")
            .ok()
            .and_then(|d| d.parse().ok())
            .unwrap_or(0),
    };
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        let value = it.next().ok_or(format!("{flag} needs a value"))?;
        let number = || value.parse::<f64>().map_err(|e| format!("{flag}: {e}"));
        match flag.as_str() {
            "--mapping" => {
                parsed.mapping = match value.as_str() {
                    "enhanced" => ServiceMapping::Enhanced,
                    "cyclone" => ServiceMapping::Cyclone,
                    other => return Err(format!("--mapping {other}: enhanced or cyclone")),
                }
            }
            "--x" => parsed.x = number()?,
            "--y" => parsed.y = number()?,
            "--seconds" => parsed.seconds = number()?,
            "--domain" => parsed.domain = value.parse().map_err(|e| format!("--domain: {e}"))?,
            other => return Err(format!("unknown {other}")),
        }
    }
    if !(parsed.x.is_finite() && parsed.y.is_finite()) {
        return Err("--x and --y are needed".into());
    }
    Ok(parsed)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args = match parse(&args) {
        Ok(a) => a,
        Err(why) => {
            eprintln!("ros2_navigate: {why}");
            return ExitCode::from(2);
        }
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("a runtime");
    let seconds = Duration::from_secs_f64(args.seconds);
    match runtime.block_on(async { tokio::time::timeout(seconds, navigate(args)).await }) {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(why)) => {
            eprintln!("ros2_navigate: {why}");
            ExitCode::from(3)
        }
        Err(_) => {
            eprintln!("ros2_navigate: no result in time");
            ExitCode::from(3)
        }
    }
}

/// Prints one event.
fn emit(event: serde_json::Value) {
    println!("{event}");
}

async fn navigate(args: Args) -> Result<(), String> {
    let participant = DomainParticipantBuilder::new(args.domain)
        .with_only_networks([std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST)])
        .build()
        .map_err(|e| format!("DDS participant: {e:?}"))?;
    let context =
        Context::from_domain_participant(participant).map_err(|e| format!("context: {e:?}"))?;
    let name = NodeName::new("/", "navigate_client").map_err(|e| format!("{e:?}"))?;
    let mut node = context
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|e| format!("node: {e:?}"))?;
    tokio::spawn(node.spinner().map_err(|e| format!("{e:?}"))?.spin());
    // rcl's defaults: reliable, keeping the last 10; the status transient local.
    let reliable = QosProfile::publisher_default().history(History::KeepLast { depth: 10 });
    let qos = ActionClientQosPolicies {
        goal_service: reliable.clone(),
        result_service: reliable.clone(),
        cancel_service: reliable.clone(),
        feedback_subscription: reliable.clone(),
        status_subscription: reliable.durability(Durability::TransientLocal),
    };
    let client = node
        .create_action_client::<
            nav2_msgs::NavigateToPoseGoal,
            nav2_msgs::NavigateToPoseResult,
            nav2_msgs::NavigateToPoseFeedback,
        >(
            args.mapping,
            &Name::new("/", "navigate_to_pose").map_err(|e| format!("{e:?}"))?,
            &ActionTypeName::new("nav2_msgs", "NavigateToPose"),
            qos,
        )
        .map_err(|e| format!("action client: {e:?}"))?;
    let goal = nav2_msgs::NavigateToPoseGoal {
        pose: geometry_msgs::PoseStamped {
            header: std_msgs::Header {
                frame_id: "map".into(),
                ..Default::default()
            },
            pose: geometry_msgs::Pose {
                position: geometry_msgs::Point {
                    x: args.x,
                    y: args.y,
                    z: 0.0,
                },
                orientation: geometry_msgs::Quaternion {
                    w: 1.0,
                    ..Default::default()
                },
            },
        },
        behavior_tree: String::new(),
    };
    // The server is found by discovery: a request before it matched goes nowhere, so the
    // goal is sent again until it is answered.
    let (goal_id, response) = loop {
        let sent =
            tokio::time::timeout(Duration::from_secs(2), client.async_send_goal(goal.clone()));
        match sent.await {
            Ok(Ok(answered)) => break answered,
            Ok(Err(e)) => return Err(format!("the goal: {e:?}")),
            Err(_) => continue,
        }
    };
    emit(json!({"event": "accepted", "accepted": response.accepted}));
    if !response.accepted {
        return Ok(());
    }
    let feedback = client.feedback_stream(goal_id);
    let result = client.async_request_result(goal_id);
    tokio::pin!(feedback);
    tokio::pin!(result);
    loop {
        tokio::select! {
            Some(Ok(f)) = feedback.next() => emit(json!({
                "event": "feedback",
                "distance_remaining": f.distance_remaining,
                "x": f.current_pose.pose.position.x,
                "y": f.current_pose.pose.position.y,
            })),
            ended = &mut result => {
                let (status, result) = ended.map_err(|e| format!("the result: {e:?}"))?;
                emit(json!({
                    "event": "result",
                    "status": format!("{status:?}"),
                    "error_code": result.error_code,
                    "error_msg": result.error_msg,
                }));
                return Ok(());
            }
        }
    }
}
