"""The identifier node in a lockstep graph: RecursiveArx's coefficients of the same samples.

The simulator (lockstep) and the excitation drive exactly ``N`` samples; the
identifier node estimates a recursive ARX on the field and current channels;
a peer node receives the same messages, assembles the samples by stamp and
runs :class:`~maglev_ros.sysid.online.OnlineArx` and
:class:`~maglev_ros.sysid.RecursiveArx` on them. The published model must be
those numbers (up to floating-point rounding).
"""

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, MagneticField
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from waiting import wait_for

from maglev_ros import topics
from maglev_ros.nodes.excitation import ExcitationNode
from maglev_ros.nodes.identifier import (
    IdentifierNode,
    IdentifierParameterError,
    build_config,
    build_identifier,
)
from maglev_ros.nodes.qos import SENSOR_QOS
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.nodes.simulator import SimulatorNode
from maglev_ros.sysid import IdData, RecursiveArx, arx
from maglev_ros.sysid.online import OnlineArx

N = 600  # samples of the run


def params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def _stamp(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


CASES = {
    # SISO: x field of sensor 0 against u_x (the x pair's antisymmetric current)
    'siso': (
        [topics.field_channel(0, 'x')],
        [f'ux=0.5*{topics.current_channel(0)}-0.5*{topics.current_channel(1)}'],
        dict(na=[2], nb=[2], nk=[0], wait_for_history=False, forgetting=0.995),
        lambda f, c: ([f[0]], [0.5 * c[0] - 0.5 * c[1]]),
    ),
    # forgetting factor 1, output in mT (the channel's scale), a weak prior: batch ARX
    'batch': (
        [f'Bx_mT=1000*{topics.field_channel(0, "x")}'],
        [f'ux=0.5*{topics.current_channel(0)}-0.5*{topics.current_channel(1)}'],
        dict(na=[2], nb=[3], nk=[0], wait_for_history=True, forgetting=1.0),
        lambda f, c: ([1000 * f[0]], [0.5 * c[0] - 0.5 * c[1]]),
    ),
    # MISO: z field of sensor 0 against u_x and u_y
    'miso': (
        [topics.field_channel(0, 'z')],
        [
            f'ux=0.5*{topics.current_channel(0)}-0.5*{topics.current_channel(1)}',
            f'uy=0.5*{topics.current_channel(2)}-0.5*{topics.current_channel(3)}',
        ],
        dict(na=[1], nb=[2, 1], nk=[0, 1], wait_for_history=True, forgetting=0.995),
        lambda f, c: ([f[2]], [0.5 * c[0] - 0.5 * c[1], 0.5 * c[2] - 0.5 * c[3]]),
    ),
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_published_model_is_recursive_arx_of_the_same_samples(ctx, case):
    outputs, inputs, orders, sample_of = CASES[case]
    wait, lam = orders['wait_for_history'], orders['forgetting']
    p0 = 1e8 if case == 'batch' else 1e6
    sim = SimulatorNode(
        context=ctx,
        parameter_overrides=params(
            mode='lockstep',
            magnet='fixed',
            coil_dynamics=False,
            start_paused=True,
            marker_rate=0.0,
            sensors=[0],
            publish_state=False,
            sensor_noise=1e-4,
            seed=7,
            command_timeout=120.0,  # no sample beyond the excitation's last command
        ),
    )
    excite = ExcitationNode(
        context=ctx,
        parameter_overrides=params(
            signal='prbs', amplitude=0.3, pattern='independent', seed=3, max_commands=N - 1
        ),
    )
    ident = IdentifierNode(
        context=ctx,
        parameter_overrides=params(
            outputs=outputs,
            inputs=inputs,
            initial_covariance=p0,
            publish_rate=50.0,
            **orders,
        ),
    )
    peer = rclpy.create_node('identifier_test_peer', context=ctx)
    fields, currents, models, diags = {}, {}, [], []
    peer.create_subscription(
        MagneticField,
        topics.field_topic(0),
        lambda m: fields.__setitem__(_stamp(m), m.magnetic_field),
        SENSOR_QOS,
    )
    peer.create_subscription(
        JointState,
        topics.CURRENTS_TOPIC,
        lambda m: currents.__setitem__(_stamp(m), list(m.effort)),
        SENSOR_QOS,
    )
    peer.create_subscription(
        Float64MultiArray, topics.IDENTIFIER_MODEL_TOPIC, lambda m: models.append(m), 10
    )
    peer.create_subscription(
        DiagnosticArray,
        topics.DIAGNOSTICS_TOPIC,
        lambda m: diags.extend((_stamp(m), s) for s in m.status if 'identifier' in s.name),
        10,
    )
    spinner = Spinner(ctx, [sim, excite, ident, peer])
    try:
        wait_for(
            lambda: (
                excite.command_subscribers >= 1
                and sim.command_publishers >= 1
                and sim.currents_subscribers >= 3
            ),
            what='discovery',
        )
        sim.set_paused(False)
        wait_for(lambda: ident.samples >= N and len(currents) >= N, what=f'{N} samples')
        n_models = len(models)
        wait_for(lambda: len(models) > n_models + 1, what='a model published after the run')
        model = models[-1]
        assert ident.samples == N and len(currents) == N
        stamps = sorted(currents)
        y, u = zip(
            *(sample_of([getattr(fields[s], a) for a in 'xyz'], currents[s]) for s in stamps),
            strict=True,
        )
        y, u = np.array(y), np.array(u)
        o = ident.identifier.arx.orders
        na, nb, nk = o.na, o.nb, o.nk
        if wait:  # the node's default: rows start once their regressor is complete
            reference = OnlineArx(na, nb, nk, 1, u.shape[1], lam, p0)
        else:  # zeros before the first sample: sysid.RecursiveArx itself
            reference = RecursiveArx(na, nb, nk, 1, u.shape[1], forgetting=lam, p0=p0)
        for yt, ut in zip(y, u, strict=True):
            reference.update(yt, ut)
        published = np.array(model.data)
        np.testing.assert_allclose(published, reference.theta, rtol=1e-9, atol=1e-15)
        if case == 'batch':  # converged to the batch ARX of the same samples
            batch = arx(IdData(y, u, 2e-4), na, nb, nk).theta
            assert np.max(np.abs(published - batch)) <= 1e-6 * np.max(np.abs(batch)), (
                published,
                batch,
            )
        assert np.all(published != 0)
        # the layout names the channels' polynomials and their offsets
        labels = [d.label for d in model.layout.dim]
        assert labels[0] == 'theta' and model.layout.dim[0].size == len(published)
        assert labels[1].startswith('A[') and ' na=' in labels[1], labels
        assert any(label.startswith('B[') and ',ux] nb=' in label for label in labels), labels
        # diagnostics: stamped, with the covariance trace and the drift
        last = [
            (t, s)
            for t, s in diags
            if dict((kv.key, kv.value) for kv in s.values)['samples'] == str(N)
        ]
        assert last, [s.message for _, s in diags[-3:]]
        stamp, status = last[-1]
        assert 0 < stamp <= ident.get_clock().now().nanoseconds  # the node's clock
        values = {kv.key: kv.value for kv in status.values}
        if wait:
            trace = reference.status().covariance_trace
            assert float(values['covariance trace']) == pytest.approx(trace, rel=1e-8)
        assert float(values['covariance trace']) > 0
        assert float(values['parameter drift']) >= 0
        assert values['incomplete stamps dropped'] == '0'
        # reset: back to theta = 0 and no samples
        client = peer.create_client(Trigger, topics.IDENTIFIER_RESET_SERVICE)
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(Trigger.Request())
        wait_for(future.done, what='reset response')
        assert future.result().success and f'{N} samples' in future.result().message
        assert ident.samples == 0 and not np.any(ident.identifier.arx.theta)
    finally:
        spinner.close()
        for node in (sim, excite, ident, peer):
            node.destroy_node()


@pytest.mark.parametrize(
    'changes, match',
    [
        ({'forgetting': 1.5}, 'forgetting must be a finite number > 0 and <= 1, got 1.5'),
        ({'initial_covariance': 0.0}, 'initial_covariance must be a finite number > 0'),
        ({'outputs': []}, 'outputs must be a non-empty list of channel specs'),
        ({'na': [-1]}, 'na must be a non-empty list of integers >= 0'),
        ({'window': -3}, 'window must be an integer >= 0, got -3'),
        ({'publish_rate': 0.0}, 'publish_rate must be a finite number > 0'),
        ({'identify_from': -1.0}, 'identify_from must be a finite number >= 0, got -1.0'),
        (
            {'identify_from': 2.0, 'identify_until': 1.5},
            r'identify_until must be 0 \(no end\) or >= identify_from 2, got 1.5',
        ),
        ({'complete_on_next': 1}, 'complete_on_next must be true or false, got 1'),
    ],
)
def test_config_errors(changes, match):
    with pytest.raises(IdentifierParameterError, match=match):
        build_config(changes)


@pytest.mark.parametrize(
    'changes, match',
    [
        ({'nb': [2, 2, 2]}, r'nb must have 1 or 1\*1 = 1 values'),
        ({'inputs': ['maglev/currents:effort[0']}, 'identifier channels/orders'),
        ({'trigger': 'elsewhere'}, "trigger topic '/elsewhere' is not read by any channel"),
    ],
)
def test_identifier_errors(changes, match):
    with pytest.raises(IdentifierParameterError, match=match):
        build_identifier(build_config(changes))
