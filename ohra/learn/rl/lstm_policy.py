"""The recurrent policy of ``PPOSettings.policy="lstm"``: sb3-contrib's actor-critic with LSTMs, saved whole.

sb3-contrib's ``RecurrentActorCriticPolicy`` leaves the LSTM's shape out of the constructor arguments it
saves, so ``policy.save`` / ``load`` rebuild it at the default 256 units and the weights no longer fit;
:class:`LstmPolicy` adds them. Imported only when an LSTM policy is built or loaded (needs sb3-contrib).
"""

from __future__ import annotations

from typing import Any

from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy


class LstmPolicy(RecurrentActorCriticPolicy):
    """``MlpLstmPolicy`` whose saved constructor arguments include the LSTM's size and layout."""

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(lstm_hidden_size=self.lstm_actor.hidden_size, n_lstm_layers=self.lstm_actor.num_layers,
                    shared_lstm=self.shared_lstm, enable_critic_lstm=self.lstm_critic is not None)
        return data
