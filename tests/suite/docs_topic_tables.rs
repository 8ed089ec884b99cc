//! The topic tables of docs/protocols/ros1.md and rosbridge.md say what the adapters'
//! tables (`api::ros1::topics::TOPICS`, `api::rosbridge::topics::TOPICS`) publish: the same
//! topics, each of the same type at the same rate, so a topic added to a table and not to
//! its page (or the other way round) fails here.

use std::collections::BTreeMap;
use std::time::Duration;

use chassisd::api::ros1::topics as ros1;
use chassisd::api::rosbridge::topics as rosbridge;
use chassisd::engine::STATUS_PERIOD;
use chassisd::vehicle::chassis::CONTROL_PERIOD;

use crate::common;

/// The rows of the table of docs/protocols/`page` whose header starts with `header`: its
/// first cell (the topic, without its backticks) to the others.
fn table(page: &str, header: &str) -> BTreeMap<String, Vec<String>> {
    let text = std::fs::read_to_string(common::repo().join("docs/protocols").join(page))
        .expect("readable page");
    let mut lines = text.lines().skip_while(|l| !l.starts_with(header));
    assert!(lines.next().is_some(), "{page}: no table {header}");
    lines
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .map(|row| {
            let mut cells = row
                .trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_owned());
            let topic = cells.next().unwrap_or_default().replace('`', "");
            (topic, cells.collect())
        })
        .collect()
}

/// "N Hz" for one message every `period`.
fn hz(period: Duration) -> String {
    format!("{} Hz", (1.0 / period.as_secs_f64()).round())
}

#[test]
fn the_ros1_page_lists_every_topic_the_node_publishes() {
    let documented = table("ros1.md", "| Topic | Type | Rate |");
    let names: Vec<&str> = ros1::TOPICS.iter().map(|t| t.name).collect();
    assert_eq!(
        documented.keys().map(String::as_str).collect::<Vec<_>>(),
        {
            let mut sorted = names.clone();
            sorted.sort_unstable();
            sorted
        },
        "docs/protocols/ros1.md's topics are not the node's"
    );
    for topic in ros1::TOPICS {
        let row = &documented[topic.name];
        assert_eq!(row[0], topic.msg_type, "{}'s type", topic.name);
        let rate = &row[1];
        let expected = match topic.publish {
            ros1::Publish::Poses { period, .. } => hz(period.unwrap_or(CONTROL_PERIOD)),
            ros1::Publish::Imu(_) => "the IMU's".to_owned(),
            ros1::Publish::Status { every, .. } => hz(STATUS_PERIOD * every as u32),
            ros1::Publish::Code(_) => "on ".to_owned(),
        };
        assert!(
            rate.starts_with(&expected),
            "{}: the page says {rate:?}, the table {expected:?}",
            topic.name
        );
    }
}

#[test]
fn the_rosbridge_page_lists_every_topic_the_server_has() {
    let documented = table("rosbridge.md", "| Topic | Type (ROS 2) | Direction, rate |");
    let mut names: Vec<&str> = rosbridge::TOPICS.iter().map(|t| t.name).collect();
    names.sort_unstable();
    assert_eq!(
        documented.keys().map(String::as_str).collect::<Vec<_>>(),
        names,
        "docs/protocols/rosbridge.md's topics are not the server's"
    );
    for topic in rosbridge::TOPICS {
        let row = &documented[topic.name];
        assert!(
            rosbridge::type_matches(topic, &row[0]),
            "{}: the page says {}, the table {}",
            topic.name,
            row[0],
            topic.msg_type
        );
        let direction = &row[1];
        let expected = match topic.flow {
            rosbridge::Flow::Subscribed => "subscribed".to_owned(),
            rosbridge::Flow::Published(rosbridge::Publish::Status { every, .. }) => {
                format!("published, {}", hz(STATUS_PERIOD * every as u32))
            }
            rosbridge::Flow::Published(rosbridge::Publish::Odometry { every, .. }) => {
                format!("published, {}", hz(CONTROL_PERIOD * every as u32))
            }
            rosbridge::Flow::Published(rosbridge::Publish::Latched(_)) => {
                "published on change, and at once to a new subscriber".to_owned()
            }
            rosbridge::Flow::Published(rosbridge::Publish::Event(_)) => {
                "published on each event".to_owned()
            }
        };
        assert!(
            direction.starts_with(&expected),
            "{}: the page says {direction:?}, the table {expected:?}",
            topic.name
        );
    }
}
