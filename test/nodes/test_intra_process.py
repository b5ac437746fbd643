"""Taps and their dispatcher (``maglev_ros.nodes.intra_process``), without ROS traffic.

A tap hands a publisher's messages to its listeners at once; with a
:class:`TapDispatcher` installed for the context, when the loop pumps it, in
the order they were given across all taps of the context (a command given
after its samples still reaches a recorder after them), and closing the
dispatcher hands on what is queued.
"""

import threading

from maglev_ros.nodes import intra_process


class _Context:  # taps and dispatchers are kept per context object
    pass


def test_taps_deliver_in_the_publishers_thread_without_a_dispatcher():
    ctx = _Context()
    got = []
    tap = intra_process.tap(ctx, '/a')
    assert intra_process.tap(ctx, '/a') is tap and intra_process.tap(_Context(), '/a') is not tap
    tap.connect(lambda msgs: got.append((threading.current_thread(), msgs)), 'test')
    tap.deliver([b'1', b'2'])
    assert got == [(threading.current_thread(), [b'1', b'2'])]


def test_a_dispatcher_defers_every_tap_of_its_context_until_pumped_in_order():
    ctx, other = _Context(), _Context()
    samples, commands, elsewhere = (intra_process.tap(c, t) for c, t in
                                    ((ctx, '/s'), (ctx, '/c'), (other, '/s')))  # fmt: skip
    got = []

    def listener(name):
        def on_messages(msgs):
            got.append((name, msgs))
            if name == 'samples' and msgs == [b's0']:  # a listener's own delivery: at once
                commands.deliver([b'from a listener'])

        return on_messages

    samples.connect(listener('samples'), 'test')
    commands.connect(listener('commands'), 'test')
    elsewhere.connect(listener('elsewhere'), 'test')
    dispatcher = intra_process.TapDispatcher()
    intra_process.dispatch_taps(ctx, dispatcher)
    try:
        for k in range(3):  # a read's samples, then the command that answers it
            samples.deliver([b's%d' % k])
            commands.deliver([b'c%d' % k])
        elsewhere.deliver([b'x'])  # another context: at once
        assert got == [('elsewhere', [b'x'])] and dispatcher.backlog == 6
        intra_process.pump_taps(other)  # no dispatcher there: nothing happens
        intra_process.pump_taps(ctx)  # the loop, once its command is sent
        assert dispatcher.backlog == 0
        samples.deliver([b'late'])  # queued until the next pump (or the close)
    finally:
        intra_process.dispatch_taps(ctx, None)
        dispatcher.close()
    expected = [('elsewhere', [b'x']), ('samples', [b's0']), ('commands', [b'from a listener'])]
    expected += [('commands', [b'c0'])]
    for k in (1, 2):
        expected += [('samples', [b's%d' % k]), ('commands', [b'c%d' % k])]
    assert got == [*expected, ('samples', [b'late'])]
    samples.deliver([b'after'])  # no dispatcher any more: at once
    assert got[-1] == ('samples', [b'after'])
