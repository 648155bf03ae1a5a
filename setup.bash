# Source this file to use SESS-GAN:  source setup.bash
# It activates the project's virtual environment (ROS 2 Jazzy wheels) and the colcon workspace.
# Run ./sessgan setup first.

_sessgan_root=$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")" && pwd)
if [ ! -f "$_sessgan_root/ros2_ws/install/setup.bash" ]; then
  echo "SESS-GAN is not set up yet: run $_sessgan_root/sessgan setup" >&2
else
  # shellcheck disable=SC1091
  source "$_sessgan_root/.venv/bin/activate"
  export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
  # shellcheck disable=SC1091
  source "$_sessgan_root/ros2_ws/install/setup.bash"
  # Keep DDS traffic on this machine unless the user opts in to a network (see README).
  export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
  # Services answer clients that are still being discovered (config/fastdds_profiles.xml).
  export FASTRTPS_DEFAULT_PROFILES_FILE="${FASTRTPS_DEFAULT_PROFILES_FILE:-$_sessgan_root/config/fastdds_profiles.xml}"
  # UDP only, no shared memory: Fast DDS 2.14 can leave a killed process's shared-memory port
  # broken for the processes that come after it (eProsima/Fast-DDS#5469, #5053), and workers
  # are killed and restarted by design. Lockstep episodes measured as fast either way.
  export FASTDDS_BUILTIN_TRANSPORTS="${FASTDDS_BUILTIN_TRANSPORTS:-UDPv4}"
  export SESSGAN_ROOT="$_sessgan_root"
fi
unset _sessgan_root
