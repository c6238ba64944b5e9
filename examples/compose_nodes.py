"""Both nodes in one process with one executor, no launch file (run: python examples/compose_nodes.py)."""
import argparse

import rclpy

from gyro_thermal_comp.nodes.compose import make_carousel_node, make_stkf_node, spin_together

parser = argparse.ArgumentParser()
parser.add_argument('--seconds', type=float, default=None, help='stop after this long (default: Ctrl-C)')
args = parser.parse_args()

rclpy.init()
stkf = make_stkf_node({'window_s': 10.0, 'state_file': '/tmp/gtc_stkf_state.json'},
                      remap={'imu/data_raw': '/vehicle/imu/data_raw'})
carousel = make_carousel_node({'max_revolution_period_s': 4.0}, namespace='wheel')
print('spinning', stkf.get_fully_qualified_name(), 'and', carousel.get_fully_qualified_name())
spin_together(stkf, carousel, timeout_sec=args.seconds)  # MultiThreadedExecutor; saves state on exit
rclpy.try_shutdown()
