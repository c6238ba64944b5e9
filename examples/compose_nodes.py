"""Both nodes in one process with one executor, no launch file (run: python examples/compose_nodes.py).

Ctrl-C or SIGTERM: each node processes what it buffered, the STKF saves its state, exit code 0.
ROS arguments apply too, e.g. `--ros-args --params-file my_params.yaml` (sections per node name)."""
import argparse
import sys

import rclpy
from rclpy.utilities import remove_ros_args

from gyro_thermal_comp.nodes.compose import init, make_carousel_node, make_stkf_node, spin_together
from gyro_thermal_comp.nodes.executors import EXECUTORS, make_executor

parser = argparse.ArgumentParser()
parser.add_argument('--seconds', type=float, default=None, help='stop after this long (default: Ctrl-C)')
parser.add_argument('--state-file', default='/tmp/gtc_stkf_state.json', help='where the STKF keeps what it learned')
parser.add_argument('--executor', choices=EXECUTORS, default='single', help="rclpy's executor (the nodes' --executor)")
args = parser.parse_args(remove_ros_args(sys.argv)[1:])

init()  # rclpy.init without rclpy's signal handlers, which would end the context before the last batch
stkf = make_stkf_node({'window_s': 10.0, 'state_file': args.state_file},
                      remap={'imu/data_raw': '/vehicle/imu/data_raw'})
carousel = make_carousel_node({'max_revolution_period_s': 4.0}, namespace='wheel')
print('spinning', stkf.get_fully_qualified_name(), 'and', carousel.get_fully_qualified_name(), flush=True)
spin_together(stkf, carousel, executor=make_executor(args.executor), timeout_sec=args.seconds)  # saves state on exit
rclpy.try_shutdown()
